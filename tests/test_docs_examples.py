"""The documentation's examples run, and the API reference has something to show.

Every ```python and ```bash block of README.md and docs/*.md is run, page by page, in a fresh
folder: the blocks of a page in order, Python blocks sharing one namespace, so a block can use
what an earlier block of its page made (a file, a variable). Bash blocks run with `bash -e` and
this interpreter's `pecs` first on PATH. A block that cannot run here (it needs a GPU, a cluster,
a user's recording) is marked by the line `<!-- not run: REASON -->` right before it; the
contributor guide (CONTRIBUTING.md) documents the convention. ```toml blocks are parsed.
"""

from __future__ import annotations

import inspect
import os
import re
import subprocess
import sys
import types
from dataclasses import dataclass
from pathlib import Path

import pecs
import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```([\w-]*)\s*$")
NOT_RUN = re.compile(r"^<!-- not run: (\S.*?) -->$")
RUN_LANGUAGES = {"python", "bash"}
# Fewer runnable blocks than this means examples were marked "not run" wholesale.
MIN_BLOCKS_RUN = 35
BLOCK_TIMEOUT_S = 120


@dataclass(frozen=True)
class Block:
    page: Path
    line: int  # 1-based line of the opening fence
    language: str
    code: str
    not_run: str | None  # the reason given by a `<!-- not run: ... -->` marker

    @property
    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def code_blocks(page: Path) -> list[Block]:
    """The fenced blocks of a page (fences at the start of a line), with their markers."""
    lines = page.read_text(encoding="utf-8").splitlines()
    blocks, i = [], 0
    while i < len(lines):
        opening = FENCE.match(lines[i])
        if not opening:
            i += 1
            continue
        end = next((j for j in range(i + 1, len(lines)) if lines[j].rstrip() == "```"), None)
        assert end is not None, f"{page.name}:{i + 1}: code block never closed"
        previous = next((lines[j].strip() for j in range(i - 1, -1, -1) if lines[j].strip()), "")
        marker = NOT_RUN.match(previous)
        code = "\n".join(lines[i + 1 : end]) + "\n"
        blocks.append(
            Block(page, i + 1, opening.group(1), code, marker.group(1) if marker else None)
        )
        i = end + 1
    return blocks


def all_blocks() -> list[Block]:
    return [block for page in PAGES for block in code_blocks(page)]


def run_bash(block: Block, folder: Path) -> None:
    env = dict(os.environ)
    # This interpreter's `pecs` (the venv under test), whatever PATH the tests were started with.
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    done = subprocess.run(
        ["bash", "-e", "-c", block.code],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
        timeout=BLOCK_TIMEOUT_S,
    )
    assert done.returncode == 0, (
        f"{block.where}: bash block exited {done.returncode}\n{block.code}\n{done.stderr[-3000:]}"
    )


def run_python(block: Block, namespace: dict[str, object]) -> None:
    try:
        exec(compile(block.code, block.where, "exec"), namespace)
    except Exception as error:
        raise AssertionError(f"{block.where}: python block failed: {error!r}") from error


@pytest.mark.parametrize("page", PAGES, ids=lambda page: page.name)
def test_page_examples_run(page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {"__name__": "__docs__"}
    for block in code_blocks(page):
        if block.not_run is not None:
            continue
        if block.language == "python":
            run_python(block, namespace)
        elif block.language == "bash":
            run_bash(block, tmp_path)
        elif block.language == "toml":
            tomllib.loads(block.code)


def test_most_examples_run() -> None:
    """The marker is for the exceptions: most runnable-language blocks must run."""
    blocks = [block for block in all_blocks() if block.language in RUN_LANGUAGES]
    run = [block for block in blocks if block.not_run is None]
    assert len(run) >= MIN_BLOCKS_RUN, f"only {len(run)} of {len(blocks)} blocks run"


def test_markers_sit_on_code_blocks() -> None:
    """A `not run` marker that is not right before a block would silently mark nothing."""
    for page in PAGES:
        lines = page.read_text(encoding="utf-8").splitlines()
        for number, line in enumerate(lines, 1):
            if not (line.lstrip().startswith("<!--") and "not run" in line):
                continue
            marker = NOT_RUN.match(line.strip())
            assert marker, f"{page.name}:{number}: write the marker as <!-- not run: REASON -->"
            following = next((text for text in lines[number:] if text.strip()), "")
            assert FENCE.match(following), f"{page.name}:{number}: marker not followed by a block"


def test_extraction_reads_markers_and_languages(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text(
        "Text\n\n```python\nx = 1\n```\n\n<!-- not run: needs a video -->\n"
        "```bash\npecs info video.mp4\n```\n\n```toml\na = 1\n```\n",
        encoding="utf-8",
    )
    blocks = code_blocks(page)
    assert [(b.language, b.line, b.not_run) for b in blocks] == [
        ("python", 3, None),
        ("bash", 8, "needs a video"),
        ("toml", 12, None),
    ]
    assert blocks[0].code == "x = 1\n"


def public_members(obj: type) -> dict[str, object]:
    """A class's own public methods and properties (dataclass fields are data, not API)."""
    members = {}
    for name, value in vars(obj).items():
        if name.startswith("_"):
            continue
        if isinstance(value, (staticmethod, classmethod)):
            value = value.__func__
        if inspect.isfunction(value) or isinstance(value, property):
            members[name] = value
        elif hasattr(value, "func") and callable(value.func):  # functools.cached_property
            members[name] = value.func
    return members


def module_members(module: types.ModuleType) -> dict[str, object]:
    """The public functions and classes a module defines (its `__all__` where it has one)."""
    names = getattr(module, "__all__", None) or [n for n in vars(module) if not n.startswith("_")]
    members = {}
    for name in names:
        value = getattr(module, name)
        defined_here = getattr(value, "__module__", None) == module.__name__
        if defined_here and (inspect.isfunction(value) or inspect.isclass(value)):
            members[name] = value
    return members


def test_every_public_name_has_a_docstring() -> None:
    """mkdocstrings leaves out what has no docstring: the API reference would miss it."""
    missing = []
    for name in pecs.__all__:
        obj = getattr(pecs, name)
        if not (
            inspect.isclass(obj) or inspect.isroutine(obj) or isinstance(obj, types.ModuleType)
        ):
            continue  # __version__: a string
        if not (obj.__doc__ or "").strip():
            missing.append(f"pecs.{name}")
        if inspect.isclass(obj):
            for member, value in public_members(obj).items():
                if not (value.__doc__ or "").strip():
                    missing.append(f"pecs.{name}.{member}")
        if isinstance(obj, types.ModuleType):  # pecs.metrics, pecs.events, ...: their own API
            for member, value in module_members(obj).items():
                if not (value.__doc__ or "").strip():
                    missing.append(f"pecs.{name}.{member}")
    assert not missing, f"no docstring: {', '.join(missing)}"
