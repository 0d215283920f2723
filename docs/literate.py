"""Turn the demos into literate Markdown pages, as DOLFINx renders its demos.

Each ``demos/demo_*.py`` becomes ``docs/demos/demo_*.md``:

- a comment block at the top of the file and the module docstring are the page's text (both are
  Markdown; the first heading is the page title);
- the code is in ``python`` code blocks;
- a comment line ``# ## Heading`` (at any indentation) ends the code block and becomes a heading of
  the page, and a comment block that starts at the first column (``# text`` or ``#: text``) is
  text between the code blocks;
- the figures of a demo that are kept in ``docs/images`` follow its text, and the source is
  linked for download.

Sphinx roles written reStructuredText-style in the docstrings (``:class:`Name```) are turned
into MyST's ``{class}`Name```. conf.py calls :func:`write_pages` when the build starts; the
pages are build products (git-ignored), and the demos are not run.
"""

import ast
import re
import shutil
from pathlib import Path

#: The figures in docs/images that each demo writes (or that are rendered from its output).
FIGURES = {
    "demo_column_collapse": ["column_collapse_a1.png"],
    "demo_elastic_bar": ["elastic_bar.png"],
    "demo_cylinder": ["fe_cylinder.png"],
    "demo_footing": ["fe_footing.png"],
    "demo_oedometer": ["fe_oedometer.png"],
    "demo_shear_band": ["shear_band.png"],
    "demo_silo": [
        "silo_paraview.png",
        "silo_maps.png",
        "silo_discharge.png",
        "silo_profiles.png",
        "silo_radius.png",
        "silo_maps_paper.png",
    ],
    "demo_silo3d": ["silo3d_section.png"],
}

HEADING = re.compile(r"^\s*# (#+ .*)$")
TEXT = re.compile(r"^#(:?)( |$)")
# Comments that are directives to tools stay in the code.
TOOL = re.compile(r"^#\s*(isort|noqa|type|fmt|pragma|ruff)\b")
ROLE = re.compile(r":(class|func|meth|mod|attr|data|obj|exc|ref|doc|math):`([^`]+)`")


def _roles(text):
    return ROLE.sub(r"{\1}`\2`", text)


def _comment_text(line):
    """The Markdown of a text comment line (``# text`` or ``#: text``)."""
    return TEXT.sub("", line, count=1)


def convert(source, name):
    """The Markdown page of one demo's source code."""
    lines = source.splitlines()
    out = []
    start = 0
    # A comment block heading the file is text.
    while start < len(lines) and (lines[start].startswith("#") and not TOOL.match(lines[start])):
        out.append(_comment_text(lines[start]))
        start += 1
    tree = ast.parse(source)
    body = tree.body
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
        if isinstance(body[0].value.value, str):
            doc = body[0].value.value
            if out:
                out.append("")
            out.extend(_roles(doc.strip("\n")).splitlines())
            start = body[0].end_lineno
    out.append("")
    for figure in FIGURES.get(name, []):
        out += [f"![{Path(figure).stem}](../images/{figure})", ""]
    out += [f"Source: {{download}}`{name}.py`", ""]

    code = []

    def flush():
        while code and not code[-1].strip():
            code.pop()
        while code and not code[0].strip():
            code.pop(0)
        if code:
            out.extend(["```python", *code, "```", ""])
        code.clear()

    i = start
    while i < len(lines):
        line = lines[i]
        heading = HEADING.match(line)
        if heading:
            flush()
            out += [_roles(heading.group(1)), ""]
        elif TEXT.match(line) and not TOOL.match(line):
            flush()
            while i < len(lines) and TEXT.match(lines[i]) and not TOOL.match(lines[i]):
                out.append(_roles(_comment_text(lines[i])))
                i += 1
            out.append("")
            continue
        else:
            code.append(line)
        i += 1
    flush()
    return "\n".join(out).rstrip("\n") + "\n"


def write_pages(demos, folder):
    """Write one page per ``demo_*.py`` in ``demos`` into ``folder``; returns the pages."""
    demos, folder = Path(demos), Path(folder)
    folder.mkdir(exist_ok=True)
    pages = []
    for path in sorted(demos.glob("demo_*.py")):
        page = folder / f"{path.stem}.md"
        text = convert(path.read_text(encoding="utf-8"), path.stem)
        # Rewrite only what changed, so that Sphinx rebuilds only those pages.
        if not page.exists() or page.read_text(encoding="utf-8") != text:
            page.write_text(text, encoding="utf-8")
        target = folder / path.name
        if not target.exists() or target.read_bytes() != path.read_bytes():
            shutil.copyfile(path, target)
        pages.append(page)
    for stale in set(folder.glob("demo_*.md")) - set(pages):
        stale.unlink()
    return pages
