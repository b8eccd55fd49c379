"""MkDocs hook (mkdocs.yml `hooks:`): links from docs/ to files elsewhere in the repository, checked and pointed there.

A page in docs/ links to `../results/paper/README.md` or `../CHANGELOG.md` so that it reads on the repository's own
file view too; the site has no such page, and MkDocs would report each as not found. Here every such link is checked
against the checkout (a missing file is a warning, so `mkdocs build --strict` fails on it) and rewritten to the
file's address in the repository, `extra.source` in mkdocs.yml (set once): `blob/` for a file, `tree/` for a folder,
`raw/` for an image. Links within docs/ are left to MkDocs's own validation.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

log = logging.getLogger("mkdocs.hooks.docs_links")

LINK = re.compile(r"(!?)\[([^\]]*)\]\(([^)\s]+)\)")
FENCE = re.compile(r"^([ \t]*(?:```|~~~))", flags=re.M)
SCHEME = re.compile(r"^[a-z][a-z0-9+.-]*:", flags=re.I)


def _rewrite(match: re.Match, page_dir: Path, docs: Path, root: Path, source: dict, where: str) -> str:
    image, text, target = match.groups()
    if SCHEME.match(target) or target.startswith(("#", "/")):
        return match.group(0)
    path, _, fragment = target.partition("#")
    resolved = (page_dir / path).resolve()
    if resolved == docs or docs in resolved.parents:
        return match.group(0)  # MkDocs checks links within the site itself
    if root not in resolved.parents or not resolved.exists():
        log.warning("%s: the link to %s names no file in the repository", where, target)
        return match.group(0)
    kind = "raw" if image else "tree" if resolved.is_dir() else "blob"
    url = f"{source['url'].rstrip('/')}/{kind}/{source['branch']}/{resolved.relative_to(root).as_posix()}"
    return f"{image}[{text}]({url}{'#' + fragment if fragment else ''})"


def on_page_markdown(markdown: str, page, config, files) -> str:
    """Rewrite the page's links outside docs/ (never inside fenced code, where a link is an example)."""
    docs = Path(config["docs_dir"]).resolve()
    root = Path(config["config_file_path"]).resolve().parent
    page_dir = Path(page.file.abs_src_path).resolve().parent
    source = config["extra"]["source"]
    parts = FENCE.split(markdown)
    out, in_code = [], False
    for part in parts:
        if FENCE.fullmatch(part):
            in_code = not in_code
            out.append(part)
            continue
        if not in_code:
            part = LINK.sub(lambda m: _rewrite(m, page_dir, docs, root, source, page.file.src_uri), part)
        out.append(part)
    return "".join(out)
