"""MkDocs hooks of the user guide (mkdocs.yml `hooks:`; plain MkDocs, no plugin).

The dated run records under docs/ (campaign-*/, design-map*/) keep each report as it was written;
a report links every figure it made, and only some figures are kept in the record. In those
folders only, a link or image whose target is not among the documentation files is rendered as
its text, marked as not kept, so `mkdocs build --strict` still fails on any other broken link.
"""

from __future__ import annotations

import posixpath
import re

RUN_RECORD = re.compile(r"^(campaign-[^/]+|design-map[^/]*)/")
LINK = re.compile(r"(!?)\[([^\]]*)\]\(([^)\s]+)\)")


def on_page_markdown(markdown, page, config, files):
    src = page.file.src_uri
    if not RUN_RECORD.match(src):
        return markdown
    known = {f.src_uri for f in files}
    here = posixpath.dirname(src)

    def repl(m: re.Match) -> str:
        bang, text, target = m.groups()
        if re.match(r"^[a-z]+:|^#|^/", target):
            return m.group(0)
        path = posixpath.normpath(posixpath.join(here, target.split("#", 1)[0]))
        if path in known:
            return m.group(0)
        return f"*{text or target} ({target}: not kept in this record)*" if bang else f"{text} ({target}, not kept)"

    return LINK.sub(repl, markdown)
