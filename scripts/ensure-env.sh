# Sourced by scripts/run-benchmark and scripts/run-tests.
# Creates .venv when it is missing (or when pyproject.toml changed) and reuses it otherwise.
#   * A system DOLFINx >= 0.9 (Debian's python3-dolfinx) is used when `python3` can import it:
#     the venv then sees the system site-packages, only this package is installed into it
#     (pip --no-deps, nothing downloaded: Debian provides every dependency, see docs/install.md)
#     and the needed imports are checked, naming the Debian packages that are missing.
#   * Otherwise a Python >= 3.12 is looked up (PATH, then pyenv) and DOLFINx comes from the
#     PyPI wheel `dolfinx-solver-real`.
set -euo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
venv="$repo/.venv"
stamp="$venv/.nnqem-stamp"
want=$(cat "$repo/pyproject.toml" | sha256sum | cut -c1-16)

system_dolfinx_ok() {
    command -v python3 >/dev/null 2>&1 || return 1
    python3 - <<'PY' >/dev/null 2>&1
import dolfinx
major, minor = (int(x) for x in dolfinx.__version__.split(".")[:2])
raise SystemExit(0 if (major, minor) >= (0, 9) else 1)
PY
}

find_python312() {
    local c
    for c in python3.12 python3.13 python3.14; do
        if command -v "$c" >/dev/null 2>&1 && "$c" -c 'import venv' >/dev/null 2>&1; then
            command -v "$c"; return 0
        fi
    done
    local root
    root=$(pyenv root 2>/dev/null || echo "$HOME/.pyenv")
    for c in "$root"/versions/3.12.*/bin/python3 "$root"/versions/3.13.*/bin/python3 \
             "$root"/versions/3.14.*/bin/python3; do
        [ -x "$c" ] && { echo "$c"; return 0; }
    done
    return 1
}

if [ -x "$venv/bin/python" ] && [ "$(cat "$stamp" 2>/dev/null)" = "$want" ]; then
    :
else
    if system_dolfinx_ok; then
        echo "[ensure-env] using the system DOLFINx ($(python3 -c 'import dolfinx; print(dolfinx.__version__)'))" >&2
        python3 -m venv --system-site-packages "$venv"
        # Debian provides every dependency: install only this package, so that pip never puts
        # PyPI wheels (numba, gmsh, pyvista, ...) over Debian's; build it with Debian's setuptools
        # (no build isolation: nothing is downloaded).
        "$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
            --no-deps --no-build-isolation -e "$repo"
        if ! "$venv/bin/python" - <<'PY'
import importlib, sys
debian = {  # import name -> Debian package
    "numpy": "python3-numpy", "numba": "python3-numba", "scipy": "python3-scipy",
    "gmsh": "python3-gmsh", "pyvista": "python3-pyvista", "matplotlib": "python3-matplotlib",
    "h5py": "python3-h5py", "pytest": "python3-pytest", "mpi4py": "python3-mpi4py",
    "petsc4py": "python3-petsc4py-real", "basix": "python3-basix", "ufl": "python3-ufl",
    "sphinx": "python3-sphinx", "myst_parser": "python3-myst-parser",  # the "test" extra (docs test)
}
missing = {}
for name, package in debian.items():
    try:
        importlib.import_module(name)
    except Exception as error:  # ImportError, or a broken extension module
        missing[package] = f"{name}: {type(error).__name__}: {error}"
if missing:
    for text in missing.values():
        print(f"[ensure-env]   cannot import {text}", file=sys.stderr)
    print("[ensure-env] error: the system DOLFINx is used, but some Python modules are missing. Install:\n"
          f"    apt-get install {' '.join(missing)}", file=sys.stderr)
    raise SystemExit(1)
PY
        then
            rm -rf "$venv"   # no stamp: the next run checks again
            exit 3
        fi
        echo "$want" > "$stamp"
    else
        if ! py=$(find_python312); then
            echo "[ensure-env] error: no Python >= 3.12 found (looked for python3.12/3.13/3.14 on PATH and in pyenv's versions)." >&2
            echo "[ensure-env] Install one (e.g. 'pyenv install 3.12' or 'apt-get install python3.12 python3.12-venv'), or install Debian's python3-dolfinx." >&2
            exit 3
        fi
        echo "[ensure-env] creating .venv with $py; DOLFINx from the PyPI wheel dolfinx-solver-real" >&2
        "$py" -m venv "$venv"
        extras="pypi,test"
        "$venv/bin/python" -m pip install --quiet --upgrade pip
        "$venv/bin/python" -m pip install --quiet -e "$repo[$extras]"
        echo "$want" > "$stamp"
    fi
fi
export PATH="$venv/bin:$PATH"
export VIRTUAL_ENV="$venv"
