"""Build the API reference (HTML, pdoc) from the packages' docstrings, and fail on what would render wrong.

``make docs`` runs ``python docs/build_api.py out/api``. It fails (exit 1, one line per problem) on:

* any warning while the modules are imported and rendered (a submodule that does not import, a name in
  ``__all__`` that does not resolve, a type annotation pdoc cannot evaluate, ...);
* a cross-reference that renders as plain text: a Sphinx-style role (``:class:`X```, ``:func:`X```,
  ``:mod:`X```, ...) whose target pdoc cannot link, because it names something imported rather than
  defined in the module (write the full dotted path), a private or undocumented name, or uses Sphinx's
  ``~`` shortening, which pdoc does not understand. pdoc itself leaves such references unlinked without
  a word, which is why this script checks them.

The reference check wraps pdoc's own ``linkify`` filter, so a reference counts as broken exactly when
pdoc renders it without a link. That is a pdoc internal, which is why ``pyproject.toml`` pins pdoc's
major versions.
"""

from __future__ import annotations

import argparse
import re
import shutil
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path

import pdoc
import pdoc.doc
import pdoc.render
from jinja2 import pass_context
from jinja2.runtime import Context
from markupsafe import Markup

ROOT = Path(__file__).resolve().parent.parent
#: The documented packages, in layer order (each imports only those before it).
PACKAGES: tuple[str, ...] = ("components", "engine", "backends", "systems", "demos", "editor", "aberrant")
#: The reST roles pdoc turns into code spans that it then tries to link.
ROLE = re.compile(r"(?::py)?:(?:mod|func|data|const|class|meth|attr|exc|obj):`([^`]+)`")
#: An inline code span that ``linkify`` left without a link.
UNLINKED = re.compile(r"<code>([^<]*)</code>")


def _where(path: object) -> str:
    """A source file relative to the repository, for messages."""
    try:
        return str(Path(str(path)).resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


def _location(doc: pdoc.doc.Doc) -> str:
    """``file:line`` of a documented object, relative to the repository."""
    lines = doc.source_lines
    return f"{_where(doc.source_file)}:{max(1, lines[0]) if lines else 1}"


def build(output: Path, modules: Sequence[str | Path]) -> list[str]:
    """Render ``modules`` (names or paths) and their submodules into ``output``; the problems found."""
    problems: set[str] = set()
    linkify = pdoc.render.env.filters["linkify"]

    @pass_context
    def checked_linkify(context: Context, code: str, namespace: str = "", shorten: bool = True) -> Markup:
        """pdoc's ``linkify``, then: which of the docstring's roles did it leave without a link?"""
        html = linkify(context, code, namespace, shorten)
        module: pdoc.doc.Module = context["module"]
        doc = module.get(namespace) if namespace else module
        roles = set(ROLE.findall(doc.docstring)) if doc is not None else set()
        for target in sorted(roles):
            if target.startswith("~"):
                problems.add(
                    f"{_location(doc)}: reference `{target}`: pdoc does not know Sphinx's `~`, write `{target[1:]}`"
                )
        unlinked = {text.removesuffix("()") for text in UNLINKED.findall(str(html))}
        for target in sorted(t for t in roles if t.removesuffix("()") in unlinked):
            problems.add(f"{_location(doc)}: reference `{target}` links to nothing in the docs of {module.modulename}")
        return html

    pdoc.render.env.filters["linkify"] = checked_linkify
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            pdoc.render.configure(docformat="restructuredtext")
            pdoc.pdoc(*modules, output_directory=output)
    finally:
        pdoc.render.env.filters["linkify"] = linkify
    problems.update(f"{_where(w.filename)}:{w.lineno}: {w.category.__name__}: {w.message}" for w in caught)
    return sorted(problems)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output", type=Path, help="folder for the HTML (replaced)")
    args = parser.parse_args(argv)
    if args.output.exists():
        shutil.rmtree(args.output)
    # Paths, not names: pdoc then documents this checkout even where another one is installed.
    problems = build(args.output, [ROOT / package for package in PACKAGES])
    for problem in problems:
        print(f"docs: {problem}", file=sys.stderr)
    if problems:
        print(f"docs: {len(problems)} problem(s); the API reference is not complete", file=sys.stderr)
        return 1
    print(f"docs: API reference in {args.output}/index.html")
    return 0


if __name__ == "__main__":
    sys.exit(main())
