"""scripts/api_coverage.py counts a small synthetic package exactly as its rules say (public
functions and methods, docstrings, annotations), and exits 1 below a threshold. It does not test the
package's own percentages: CI runs the script for those."""

import importlib.util
import subprocess
import sys
import textwrap
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "api_coverage.py"

MODULE = '''\
"""A synthetic module."""


def documented_and_annotated(x: int, *args: float, **kwargs: str) -> int:
    """Both."""
    return x


def documented_only(x):
    """A docstring, no annotations."""
    return x


def no_return_annotation(x: int):
    """Parameters annotated, the return value not."""
    return x


def annotated_only(x: int) -> int:
    return x


def unannotated_varargs(x: int, *args) -> None:
    """``*args`` needs an annotation too."""


def _private(x):
    return x


class Public:
    """Its public methods count."""

    def __init__(self, x):
        self.x = x

    def method(self, y: int) -> int:
        """``self`` needs no annotation."""
        return y

    @classmethod
    def build(cls, y: int) -> "Public":
        """``cls`` needs no annotation."""
        return cls(y)

    @staticmethod
    def self_is_a_parameter(self: int) -> int:
        return self

    @staticmethod
    def static(self) -> int:
        """A staticmethod's first parameter is an ordinary one."""
        return 0

    @property
    def value(self) -> int:
        return self.x

    def _helper(self):
        return None

    class Inner:
        """Nested classes count too."""

        def inner(self):
            """No return annotation."""


class _Private:
    def hidden(self):
        return None
'''


def load_script():
    """The script as a module (it lives outside the package)."""
    spec = importlib.util.spec_from_file_location("api_coverage", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["api_coverage"] = module  # dataclasses resolve the module by name
    spec.loader.exec_module(module)
    return module


def make_package(root: Path) -> Path:
    package = root / "pkg"
    (package / "sub").mkdir(parents=True)
    (package / "_hidden").mkdir()
    (package / "__init__.py").write_text("def exported() -> None:\n    \"\"\"Counted.\"\"\"\n")
    (package / "sub" / "__init__.py").write_text("")
    (package / "sub" / "module.py").write_text(MODULE)
    (package / "_private_module.py").write_text("def not_counted(x):\n    return x\n")
    (package / "_hidden" / "module.py").write_text("def not_counted(x):\n    return x\n")
    return package


def test_the_script_counts_public_functions_docstrings_and_annotations(tmp_path):
    script = load_script()
    package = make_package(tmp_path)
    found = {f.name: (f.has_docstring, f.is_annotated) for f in script.public_functions([package])}
    assert found == {
        "exported": (True, True),
        "documented_and_annotated": (True, True),
        "documented_only": (True, False),
        "no_return_annotation": (True, False),
        "annotated_only": (False, True),
        "unannotated_varargs": (True, False),
        "Public.method": (True, True),
        "Public.build": (True, True),
        "Public.self_is_a_parameter": (False, True),
        "Public.static": (True, False),
        "Public.value": (False, True),
        "Public.Inner.inner": (True, False),
    }


def test_init_needs_no_return_annotation():
    script = load_script()
    init, other = (script.ast.parse(textwrap.dedent(f"""
        class A:
            def {name}(self, x: int):
                pass
        """)).body[0].body[0] for name in ("__init__", "method"))
    assert script.is_annotated(init, is_method=True)
    assert not script.is_annotated(other, is_method=True)


def test_the_script_prints_the_percentages_lists_the_missing_and_exits_1_below_a_threshold(tmp_path):
    package = make_package(tmp_path)

    def run(*options):
        return subprocess.run([sys.executable, str(SCRIPT), str(package), *options],
                              capture_output=True, text=True)

    # 12 public functions: 9 with a docstring (75.0 %), 7 annotated (58.3 %)
    passing = run("--min-docstrings", "75", "--min-annotations", "58")
    assert passing.returncode == 0, passing.stderr
    assert "public functions 12: docstrings 75.0 %, annotations 58.3 %" in passing.stdout
    assert "no docstring" not in passing.stdout

    for options in (["--min-docstrings", "76"], ["--min-annotations", "59"]):
        failing = run(*options)
        assert failing.returncode == 1, options
        assert "below the threshold" in failing.stderr

    missing = run("--missing").stdout
    assert f"{package / 'sub' / 'module.py'}: 11 public, 3 without docstring, 5 not annotated" in missing
    assert "Public.Inner.inner: no annotations" in missing
    assert "annotated_only: no docstring" in missing
    assert "exported" not in missing and "not_counted" not in missing
