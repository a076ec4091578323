"""Read the leaderboard's web pages back without a browser: each table section's Markdown link,
its rows' cell texts and the facts, with the standard library's HTML parser."""

from __future__ import annotations

from dataclasses import dataclass, field
from html.parser import HTMLParser


@dataclass
class Section:
    id: str
    source: str
    protocol: str
    md: str = ""
    header: list[str] = field(default_factory=list)
    rows: list[list[str]] = field(default_factory=list)  # every cell's shown text
    intervals: list[list[str]] = field(default_factory=list)  # "" where a cell has none


class _Reader(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.sections: list[Section] = []
        self.problems: list[str] = []
        self.placeholders: list[str] = []
        self._stack: list[tuple[str, dict[str, str]]] = []
        self._text: list[str] = []
        self._interval: list[str] = []
        self._where = ""

    def handle_starttag(self, tag: str, attrs_list: list[tuple[str, str | None]]) -> None:
        attrs = {k: v or "" for k, v in attrs_list}
        classes = attrs.get("class", "").split()
        if tag == "section" and "lb-table" in classes:
            self.sections.append(Section(attrs["id"], attrs["data-source"], attrs["data-protocol"]))
        if tag == "a" and "source-md" in classes and self.sections:
            self.sections[-1].md = attrs["href"].removeprefix("../")
        if tag in ("td", "th"):
            self._text, self._interval, self._where = [], [], "cell"
        if tag == "span" and "interval" in classes:
            self._where = "interval"
        if tag == "tr" and self.sections and self._in("tbody"):
            self.sections[-1].rows.append([])
            self.sections[-1].intervals.append([])
        if tag == "div" and "placeholder" in classes:
            self._where = "placeholder"
            self._text = []
        self._stack.append((tag, attrs))

    def _in(self, tag: str) -> bool:
        return any(t == tag for t, _ in self._stack)

    def handle_endtag(self, tag: str) -> None:
        while self._stack:
            top, _ = self._stack.pop()
            if top == tag:
                break
        if tag == "span" and self._where == "interval":
            self._where = "cell"
        if tag == "div" and self._where == "placeholder":
            self.placeholders.append("".join(self._text).strip())
            self._where = ""
        if tag == "th" and self.sections and self._in("thead") and self._in("section"):
            self.sections[-1].header.append("".join(self._text).strip())
        if tag == "td" and self.sections and self._in("tbody") and not self._in("dialog"):
            self.sections[-1].rows[-1].append("".join(self._text).strip())
            self.sections[-1].intervals[-1].append("".join(self._interval).strip())

    def handle_data(self, data: str) -> None:
        if self._where == "interval":
            self._interval.append(data)
        else:
            self._text.append(data)


def read_page(text: str) -> _Reader:
    reader = _Reader()
    reader.feed(text)
    return reader


def markdown_rows(markdown: str) -> tuple[list[str], list[list[str]]]:
    """Header and row cells of the first table in a Markdown file, bold markers removed."""
    lines: list[str] = []
    for line in markdown.splitlines():
        if line.startswith("|"):
            lines.append(line)
        elif lines:
            break
    cells = [[c.strip().replace("**", "").replace("\\|", "|") for c in line.strip("|").split(" | ")]
             for line in lines]
    return cells[0], cells[2:]
