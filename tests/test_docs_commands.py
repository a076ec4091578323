"""Every command shown in README.md and docs/ is run, so the docs cannot drift.

The fenced ```bash / ```console / ```python blocks are extracted. An HTML comment on the line
before a block may say how it is run:

    <!-- docs-test: skip REASON -->   not run (it needs real KITTI, the network, hours, or it is
                                       the project's own install); its safl-bench commands are
                                       still parsed by the CLI's own parser, so a renamed option
                                       fails here
    <!-- docs-test: slow REASON -->   run only with `pytest -m slow`, on the machine's own
                                       $SAFL_HOME (e.g. the synthetic default, minutes)

Blocks without a comment run in the default test run, each command through the CLI's entry
point (Python blocks in a fresh interpreter) in a scratch folder that holds the small data the tests make: BEVPlace-layout images at
`BEVPlace/data/KITTI` (sequences 00, 02), a KITTI odometry folder standing in for `/data/kitti`
(00, 09), and leaderboard records at `leaderboard/records`; $SAFL_HOME is a scratch folder too.
Every command must exit 0.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import write_bev, write_kitti
from site_board import write_board

from safl_bench.cli import build_parser
from safl_bench.cli import main as cli_main

REPO = Path(__file__).resolve().parents[1]
DOCS = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
LANGS = ("bash", "console", "python")
DIRECTIVE = re.compile(r"<!--\s*docs-test:\s*(skip|slow)\s+(.+?)\s*-->")
KITTI_PLACEHOLDER = "/data/kitti"


@dataclass(frozen=True)
class Block:
    file: Path
    line: int  # 1-based line of the opening fence
    lang: str
    text: str
    mode: str  # "run", "slow" or "skip"
    reason: str

    @property
    def where(self) -> str:
        return f"{self.file.relative_to(REPO)}:{self.line}"

    def commands(self) -> list[list[str]]:
        """Shell blocks: each command's words (continuations joined, comments dropped, split at
        `&&`)."""
        joined = re.sub(r"\\\n\s*", " ", self.text)
        out: list[list[str]] = []
        for line in joined.splitlines():
            words = shlex.split(line.removeprefix("$ "), comments=True)
            current: list[str] = []
            for word in [*words, "&&"]:
                if word == "&&":
                    if current:
                        out.append(current)
                    current = []
                else:
                    current.append(word)
        return out


def blocks() -> list[Block]:
    found: list[Block] = []
    for path in DOCS:
        lines = path.read_text(encoding="utf-8").splitlines()
        i = 0
        while i < len(lines):
            stripped = lines[i].strip()
            if stripped.startswith("```") and stripped[3:].strip() in LANGS:
                indent = lines[i][: len(lines[i]) - len(lines[i].lstrip())]
                j = i + 1
                while j < len(lines) and lines[j].strip() != "```":
                    j += 1
                body = "\n".join(line.removeprefix(indent) for line in lines[i + 1 : j])
                k = i - 1
                while k >= 0 and not lines[k].strip():
                    k -= 1
                match = DIRECTIVE.search(lines[k]) if k >= 0 else None
                mode, reason = (match.group(1), match.group(2)) if match else ("run", "")
                found.append(Block(path, i + 1, stripped[3:].strip(), body, mode, reason))
                i = j
            elif stripped.startswith("```"):  # another language's fence: skip over its body
                j = i + 1
                while j < len(lines) and not lines[j].strip().startswith("```"):
                    j += 1
                i = j
            i += 1
    return found


BLOCKS = blocks()


def _is_cli(words: list[str]) -> bool:
    return words[:1] == ["safl-bench"] or words[:3] == ["python", "-m", "safl_bench"]


def _cli_args(words: list[str]) -> list[str]:
    return words[1:] if words[0] == "safl-bench" else words[3:]


def test_the_docs_have_commands_and_every_directive_gives_a_reason() -> None:
    files = {b.file for b in BLOCKS}
    assert REPO / "README.md" in files and len(files) >= 10
    for path in DOCS:
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if "docs-test" in line:
                assert DIRECTIVE.search(line), f"{path}:{n}: write <!-- docs-test: skip|slow REASON -->"
    assert any(b.mode == "run" and b.lang != "python" for b in BLOCKS)


@pytest.mark.parametrize("block", [b for b in BLOCKS if b.lang != "python"], ids=lambda b: b.where)
def test_every_safl_bench_command_parses(block: Block) -> None:
    """Run or not, each safl-bench command in the docs is one the installed parser accepts."""
    for words in block.commands():
        if not _is_cli(words):
            assert block.mode == "skip", (
                f"{block.where}: `{' '.join(words)}` is not a safl-bench command; mark the block "
                "<!-- docs-test: skip REASON --> or show a safl-bench command")
            continue
        argv = _cli_args(words)
        try:
            build_parser(argv).parse_args(argv)
        except SystemExit as exc:
            if exc.code not in (0, None):  # --help / --version exit 0
                raise AssertionError(f"{block.where}: `{' '.join(words)}` does not parse") from None


@pytest.fixture(scope="module")
def small_data(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    work = tmp_path_factory.mktemp("docs-work")
    kitti = work / "kitti"
    for sequence in ("00", "09"):
        # 52 scans: 13 paper-protocol queries at every 4th frame, the last 3 scored (the first
        # 10 are context)
        write_kitti(kitti, sequence, n=52)
    bev = work / "BEVPlace" / "data" / "KITTI"
    for sequence in ("00", "02"):
        write_bev(bev, sequence)
    write_board(work)
    return {"work": work, "kitti": kitti, "home": work / "home"}


def _run(block: Block, cwd: Path, env: dict[str, str], kitti: Path | None,
         monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """Python blocks in a fresh interpreter (they register methods); safl-bench commands in this
    process, as `safl-bench` runs them (`cli.main`), in `cwd` with `env`."""
    if block.lang == "python":
        done = subprocess.run([sys.executable, "-c", block.text], cwd=cwd, env=env,
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, f"{block.where}: the Python block failed:\n{done.stderr[-3000:]}"
        return
    monkeypatch.chdir(cwd)
    for name in set(os.environ) - set(env):
        monkeypatch.delenv(name)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    for words in block.commands():
        argv = _cli_args(words)
        if kitti is not None:
            argv = [a.replace(KITTI_PLACEHOLDER, str(kitti)) for a in argv]
        code = cli_main(argv)
        out = capsys.readouterr()
        assert code == 0, (f"{block.where}: `{' '.join(words)}` exited {code}:\n"
                           f"{out.out[-2000:]}\n{out.err[-3000:]}")


def _env(home: Path | None) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH", "")) if p)
    env.pop("SAFL_RESULTS", None)
    if home is not None:
        env["SAFL_HOME"] = str(home)
    return env


@pytest.mark.parametrize("block", [b for b in BLOCKS if b.mode == "run"], ids=lambda b: b.where)
def test_docs_command_runs_on_small_data(block: Block, small_data: dict[str, Path],
                                        monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    _run(block, small_data["work"], _env(small_data["home"]), small_data["kitti"], monkeypatch, capsys)


@pytest.mark.slow
@pytest.mark.parametrize("block", [b for b in BLOCKS if b.mode == "slow"], ids=lambda b: b.where)
def test_slow_docs_command_runs(block: Block, small_data: dict[str, Path],
                               monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    """Slow blocks run on this machine's own $SAFL_HOME (the synthetic default is generated or
    reused there), in a scratch folder, KITTI lines on the small KITTI folder."""
    _run(block, small_data["work"], _env(None), small_data["kitti"], monkeypatch, capsys)


def test_the_cli_reference_page_is_printed_by_the_parser() -> None:
    from safl_bench.cli import COMMANDS
    from safl_bench.cli.reference import cli_reference_markdown

    page = cli_reference_markdown()
    for name, target in COMMANDS.items():
        words = [f"{name} {sub}" for sub in target] if isinstance(target, dict) else [name]
        for command in words:
            assert f"`safl-bench {command}`" in page
    assert "--no-site" in page and "--bev-root" in page  # options come from the parser itself
    from safl_bench.cli.reference import PAGE, with_reference

    committed = PAGE.read_text(encoding="utf-8")
    assert with_reference(committed) == committed, (
        "docs/reference/cli.md is stale: run python -m safl_bench.cli.reference")


def test_the_readme_is_a_short_front_door() -> None:
    """At most 200 lines; its set-up is two commands, one that installs and runs the main job
    on the embedded default (the bare name the project is known by), one that installs and runs
    the tests; and one meaning of bold (the headline's), Table II marking its cells otherwise."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200
    setup = text.split("## Set-up", 1)[1].split("\n## ", 1)[0]
    commands = re.findall(r"```bash\n(.*?)\n```", setup, flags=re.S)
    assert len(commands) == 2
    assert commands[0].startswith("python3 -m venv") and commands[0].endswith("safl-bench run --method stable_afl")
    assert commands[1].startswith("python3 -m venv") and commands[1].endswith("python -m pytest -q")
    table2 = text.split("<!-- table2:start -->", 1)[1].split("<!-- table2:end -->", 1)[0]
    assert "**" not in table2
