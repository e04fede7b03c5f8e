"""docs/problem-file.md and the problem-file reader cannot drift: the same sections and keys both
ways, the same defaults, and ``run --help`` points to the page."""

import dataclasses
import re
import tomllib
from pathlib import Path

import pytest
from problem_files import two_beams_minimal

from dolfinx_nnqem.cli import main
from dolfinx_nnqem.problem_file import KEYS, SECTIONS, load_problem_file

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "problem-file.md"
HEADING = re.compile(r"^## `\[+([\w.]+)\]+`")
ROW = re.compile(r"^\| `(\w+)` \|")


def documented() -> dict[str, dict[str, list[str]]]:
    """{section: {key: [type, unit, default, meaning, example]}} from the page's tables."""
    sections: dict[str, dict[str, list[str]]] = {}
    current = None
    for line in DOC.read_text().splitlines():
        heading = HEADING.match(line)
        if heading:
            current = sections.setdefault(heading.group(1), {})
        elif line.startswith("## "):
            current = None  # a section of prose (the example, the command line)
        elif current is not None and ROW.match(line):
            cells = [c.strip() for c in line.strip().strip("|").split(" | ")]
            current[ROW.match(line).group(1)] = cells[1:]
    return sections


def test_every_key_the_reader_accepts_is_documented_and_no_other():
    doc = documented()
    code = {section: set(keys) for section, keys in KEYS.items()}
    print(f"\n  {sum(map(len, doc.values()))} keys in {len(doc)} sections documented; "
          f"{sum(map(len, code.values()))} in {len(code)} accepted")
    missing = {s: sorted(k - set(doc.get(s, {}))) for s, k in code.items() if k - set(doc.get(s, {}))}
    extra = {s: sorted(set(k) - code.get(s, set())) for s, k in doc.items() if set(k) - code.get(s, set())}
    assert not missing, f"accepted but not documented: {missing}"
    assert not extra, f"documented but not accepted: {extra}"
    assert {s.split(".")[0] for s in doc} == SECTIONS


def test_every_row_has_type_unit_default_meaning_and_example():
    for section, rows in documented().items():
        for key, cells in rows.items():
            assert len(cells) == 5 and all(cells), f"[{section}].{key}: {cells}"


def _literal(cell: str):
    """A default written as one TOML value in backticks, else None (prose: 'required', 'E·h')."""
    match = re.fullmatch(r"`([^`]+)`", cell)
    if not match:
        return None
    try:
        return tomllib.loads(f"v = {match.group(1)}")["v"]
    except tomllib.TOMLDecodeError:
        return None


def test_documented_defaults_are_the_readers(tmp_path):
    (tmp_path / "p.toml").write_text(
        two_beams_minimal(materials="[materials.1]\nE = 1.0\nnu = 0.3", mu_f=0.1, clamped=(11,)))
    spec = load_problem_file(tmp_path / "p.toml")
    from dolfinx_nnqem.contact.specification import Contact

    contact_defaults = {f.name: f.default for f in dataclasses.fields(Contact)}
    actual = {"solver": spec.solver, "output": spec.output, "checks": spec.checks, "estimate": spec.estimate,
              "mesh": spec.mesh, "materials.TAG": vars(spec.materials[1]) if hasattr(spec.materials[1], "__dict__")
              else dataclasses.asdict(spec.materials[1]), "contact": contact_defaults}
    compared = 0
    for section, rows in documented().items():
        for key, cells in rows.items():
            default = _literal(cells[2])
            if default is None or section not in actual or key not in actual[section]:
                continue
            value = actual[section][key]
            print(f"\n  [{section}].{key}: documented {default!r}, reader {value!r}", end="")
            assert value == pytest.approx(default) if isinstance(default, float) else value == default, \
                f"[{section}].{key}: documented default {default!r}, the reader gives {value!r}"
            compared += 1
    assert compared >= 15, f"only {compared} defaults compared"


def test_run_help_points_to_the_reference(capsys):
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "docs/problem-file.md" in text and "--no-pictures" in text
