"""MkDocs hooks (mkdocs.yml `hooks:`): pages generated at build time, never committed.

- reference/scene.md: the scene reference (scripts/docs_pages.scene_reference), from the
  parser's own key sets and defaults.
- results/*.png, results/demo/*.png: the committed figures, served beside the pages.
- guide/jobs.md: jobs/README.md (the batch scripts' documentation, kept beside them).
- `<!-- bench: NAME -->` in a page: replaced by the table docs_pages.BENCHMARKS[NAME] renders
  from results/*.json.
"""
from __future__ import annotations

import glob
import os
import sys

from mkdocs.structure.files import File

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [p for p in (ROOT, os.path.join(ROOT, "scripts")) if p not in sys.path]

import docs_pages  # noqa: E402


def on_files(files, config):
    files.append(File.generated(config, "reference/scene.md", content=docs_pages.scene_reference()))
    for png in sorted(glob.glob(os.path.join(ROOT, "results", "*.png"))
                      + glob.glob(os.path.join(ROOT, "results", "demo", "*.png"))):
        files.append(File.generated(config, os.path.relpath(png, ROOT), abs_src_path=png))
    with open(os.path.join(ROOT, "jobs", "README.md")) as f:     # the job scripts' own page
        files.append(File.generated(config, "guide/jobs.md", content=f.read()))
    return files


def on_page_markdown(markdown, page, config, files):
    return docs_pages.render_markers(markdown)
