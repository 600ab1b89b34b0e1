"""Every "paper 00N <place>" in the code and the docs resolves through docs/references.md:
the paper is named there, the form of the place is one it documents, and the place is
within what that paper holds (its table of sections, equations, figures...)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
REFERENCES = ROOT / "docs" / "references.md"

#: The words a citation may use for a place, by the column of the references' table.
KINDS = {
    "sections": ("section", "sections", "sec.", "s."),
    "equations": ("eq.", "eqs."),
    "figures": ("fig.", "figs.", "figure", "figures"),
    "tables": ("table", "tables"),
    "footnotes": ("footnote",),
    "examples": ("example", "examples"),
    "cases": ("case", "cases"),
    "algorithms": ("algorithm", "algorithms"),
}
WORD = {word: kind for kind, words in KINDS.items() for word in words}
PLACE = "|".join(re.escape(w) for w in sorted(WORD, key=len, reverse=True))
#: "paper 001 eq. 25-27", "Paper 002, sections 3-4", "paper 001 (section II", "tables 2 and 3"
CITATION = re.compile(
    rf"[Pp]aper (00\d)[ ,;:(]+({PLACE}) ?((?:[0-9IVX]+|[a-d]\b)(?:[.-][0-9A-Z]+)*"
    rf"(?:(?:-| and |, )(?:[0-9IVX]+|[a-d]\b)(?:[.-][0-9A-Z]+)*)*)",
    re.IGNORECASE,
)
ROMAN = {"I": 1, "II": 2, "III": 3, "IV": 4, "V": 5, "VI": 6, "VII": 7}


def _number(token: str) -> int:
    """The leading number of a place: ``"III-C-2"`` -> 3, ``"3.1"`` -> 3, ``"b"`` -> 2."""
    head = re.split(r"[.-]", token)[0]
    if head in ROMAN:
        return ROMAN[head]
    if head.isdigit():
        return int(head)
    assert len(head) == 1 and head in "abcd", token
    return "abcd".index(head) + 1


def _numbers(places: str) -> list[int]:
    """The places a citation names: ``"25-27"`` -> [25, 27] (a range, both ends checked),
    ``"2 and 3"`` -> [2, 3], ``"III-C-2"`` -> [3] (one section with its sub-parts)."""
    out = []
    for item in re.split(r" and |, ", places):
        parts = item.split("-")
        if len(parts) == 2 and all(p.isdigit() or p in ROMAN for p in parts):
            out += [_number(parts[0]), _number(parts[1])]
        else:
            out.append(_number(item))
    return out


def _range(cell: str) -> tuple[int, int] | None:
    """``"1-14"`` -> (1, 14), ``"I-V"`` -> (1, 5), ``"-"`` -> None."""
    if cell.strip() == "-":
        return None
    low, high = cell.strip().split("-")
    return _number(low), _number(high)


def holdings() -> dict[str, dict[str, tuple[int, int] | None]]:
    """The references' table of places, by paper and kind."""
    text = REFERENCES.read_text(encoding="utf-8")
    header = next(line for line in text.splitlines() if line.startswith("| paper | sections"))
    columns = [c.strip() for c in header.strip("|").split("|")]
    out = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if line.startswith("| 00") and len(cells) == len(columns):
            out[cells[0]] = {k: _range(v) for k, v in zip(columns[1:], cells[1:], strict=True)}
    return out


def _sources() -> list[Path]:
    """The repository's Python files, its docs and its README."""
    files = [p for p in ROOT.rglob("*.py") if not {".venv", "runs"} & set(p.parts)]
    return files + [*(ROOT / "docs").glob("*.md"), ROOT / "README.md"]


def citations() -> list[tuple[str, ...]]:
    """``(file, paper, place word, places)`` of every citation with a place in the
    repository's Python files and docs (f-string placeholders have no place and are left out)."""
    found: list[tuple[str, ...]] = []
    for path in _sources():
        text = path.read_text(encoding="utf-8")
        found.extend((str(path.relative_to(ROOT)), *m.groups()) for m in CITATION.finditer(text))
    return found


def test_the_references_name_every_cited_paper():
    text = REFERENCES.read_text(encoding="utf-8")
    named = set(re.findall(r"\*\*paper (00\d)\*\*", text))
    assert named == {"000", "001", "002", "004"}
    cited = set()
    for path in _sources():
        text = path.read_text(encoding="utf-8").replace("there is no paper 003", "")
        cited |= set(re.findall(r"[Pp]aper (00\d)", text))
    assert cited and cited <= named, cited - named
    assert set(holdings()) == named


def test_every_place_word_is_documented():
    text = REFERENCES.read_text(encoding="utf-8").lower()
    for word in ("eq. k", "section s", "sec. s", "s. s", "fig. k", "figure k", "table k"):
        assert f'"{word}' in text, word
    for word in ("footnote k", "example k", "case a", "algorithm i"):
        assert f'"{word}"' in text, word


def test_every_cited_place_is_in_its_paper():
    held = holdings()
    found = citations()
    assert len(found) > 50  # the code cites its papers throughout
    wrong = [
        f"{source}: paper {paper} {word} {places} ({WORD[word.lower()]}: {span})"
        for source, paper, word, places in found
        for span in [held[paper][WORD[word.lower()]]]
        for number in _numbers(places)
        if span is None or not span[0] <= number <= span[1]
    ]
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize(
    ("text", "places"),
    [
        ("paper 001 section III-C-2, table I", "III-C-2"),
        ("Paper 002, sections 3-4:", "3-4"),
        ("paper 004 tables 2 and 3", "2 and 3"),
        ("paper 001 (section II, eq. 1-17", "II"),
    ],
)
def test_the_citation_pattern_reads_the_forms_in_use(text, places):
    match = CITATION.search(text)
    assert match is not None and match.group(3) == places


def test_a_place_beyond_the_paper_is_caught():
    """The check can fail: paper 002 has 7 equations and no table."""
    held = holdings()
    assert held["002"]["equations"] == (1, 7) and held["002"]["tables"] is None
    assert _number("8") > held["002"]["equations"][1]
