# dolfinx_nnqem on Debian 13 (trixie) with Debian's DOLFINx 0.9 (python3-dolfinx-real).
# The same environment as scripts/debian-test (which builds it with mmdebstrap where no container
# engine runs); keep the package list in step with that script. See docs/install.md.
#
#   docker build -t dolfinx_nnqem:trixie .
#   docker run --rm dolfinx_nnqem:trixie                              # the default test suite
#   docker run --rm dolfinx_nnqem:trixie scripts/run-tests -m slow    # pytest arguments
#   docker run --rm -it dolfinx_nnqem:trixie bash                     # a shell (.venv on PATH)
FROM debian:trixie

ENV DEBIAN_FRONTEND=noninteractive LANG=C.UTF-8

# Everything from apt, no Recommends (as in scripts/debian-test). DOLFINx/basix/FFCx 0.9, UFL 2024.2,
# PETSc 3.22 with petsc4py, OpenMPI 5 with mpi4py, numba, pyvista/VTK 9.3, gmsh, scipy, matplotlib,
# h5py, pytest, Sphinx + MyST (the docs test); FFCx's JIT compiler toolchain comes with them.
RUN apt-get update \
 && apt-get install -y --no-install-recommends \
        python3-dolfinx-real python3-pytest python3-pytest-xdist python3-numba python3-pyvista python3-gmsh python3-scipy \
        python3-matplotlib python3-h5py python3-sphinx python3-myst-parser \
        python3-venv python3-pip python3-setuptools xvfb xauth \
 && rm -rf /var/lib/apt/lists/*

# OpenMPI refuses to start as root unless told; btl self,sm silences the TCP pairing warning; the
# MPI tests use 3 ranks, more than a small machine's cores (OpenMPI 5 reads the PRTE variable).
ENV OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl=self,sm \
    PRTE_MCA_rmaps_default_mapping_policy=:oversubscribe

# Only what the package and its tests need: never the host's .venv (a PyPI venv would be reused by
# ensure-env.sh, its stamp being the hash of pyproject.toml), results/ or caches.
WORKDIR /srv/dolfinx_nnqem
COPY pyproject.toml README.md ./
COPY scripts scripts
COPY dolfinx_nnqem dolfinx_nnqem
COPY tests tests
COPY demos demos
COPY meshes meshes
COPY docs docs

# The README's environment step, "system DOLFINx" branch: .venv with --system-site-packages (Debian's
# Python is EXTERNALLY-MANAGED; a venv keeps pip away from /usr) and `pip install --no-deps
# --no-build-isolation -e .` (nothing comes from PyPI: numba, gmsh, ... stay Debian's), then a check
# of every needed import, naming the missing Debian packages.
RUN bash -c 'source scripts/ensure-env.sh'
ENV VIRTUAL_ENV=/srv/dolfinx_nnqem/.venv PATH=/srv/dolfinx_nnqem/.venv/bin:$PATH

# Debian's VTK renders only through X: pyvista needs xvfb-run. xvfb-run must not be PID 1 (it then
# waits forever for Xvfb's ready signal), hence a shell that does not exec it ("; exit $?").
# The command is the README's `scripts/run-tests` (= `python -m pytest` in .venv: Debian's
# /usr/bin/pytest would run the system Python, which does not see the editable install).
ENTRYPOINT ["/bin/bash", "-c", "xvfb-run -a \"$@\"; exit $?", "--"]
CMD ["scripts/run-tests"]
