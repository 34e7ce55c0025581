"""MkDocs hooks (mkdocs.yml `hooks:`). Every page a link names is a file under docs/, so that
links resolve on the repository as on the site:

- reference/scene.md: the scene reference (scripts/docs_pages.scene_reference), from the
  parser's own key sets and defaults; committed, and the build stops when it is stale
  (`python scripts/docs_pages.py scene > docs/reference/scene.md` regenerates it).
- results/ (a symlink to the repository's results/; mkdocs.yml serves only its figures) and
  guide/jobs.md (a symlink to jobs/README.md, kept beside the batch scripts).
- `<!-- bench: NAME -->` in a page: replaced by the table docs_pages.BENCHMARKS[NAME] renders
  from results/*.json.
"""
from __future__ import annotations

import os
import sys

from mkdocs.exceptions import PluginError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [p for p in (ROOT, os.path.join(ROOT, "scripts")) if p not in sys.path]

import docs_pages  # noqa: E402


def on_files(files, config):
    stale = docs_pages.stale_scene_reference()
    if stale:
        raise PluginError(stale)
    return files


def on_page_markdown(markdown, page, config, files):
    return docs_pages.render_markers(markdown)
