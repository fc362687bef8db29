"""MkDocs hooks (mkdocs.yml `hooks:`): serve the scene library's pictures from scenes/.

The gallery page links them as `../scenes/NAME/events.png`, which is right where GitHub renders
docs/gallery.md. MkDocs only serves files under docs/, so the pictures are added to the site as
`scenes/NAME/*.png` and the links of pages at the top of docs/ rewritten to match: one copy of
each picture in the repository, and the strict build still checks every link.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from mkdocs.structure.files import File, Files

SCENES = Path(__file__).resolve().parent.parent / "scenes"


def on_files(files: Files, config: Any) -> Files:
    """Add scenes/*/*.png to the site, at the same path under its root."""
    for picture in sorted(SCENES.glob("*/*.png")):
        uri = f"scenes/{picture.parent.name}/{picture.name}"
        files.append(File.generated(config, uri, abs_src_path=str(picture)))
    return files


def on_page_markdown(markdown: str, page: Any, config: Any, files: Files) -> str:
    """`../scenes/` from a page at the top of docs/ is `scenes/` on the site."""
    if "/" in page.file.src_uri:
        return markdown
    return markdown.replace("](../scenes/", "](scenes/")
