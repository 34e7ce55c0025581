"""VTU export (`hpcwedge export`): one whole-body configuration (recovery.Configuration) as a
VTK XML unstructured grid for ParaView, written atomically (files.replace_atomic)."""
from __future__ import annotations

import math
import os

import numpy as np

from hpcwedge.files import replace_atomic
from hpcwedge.post.recovery import Configuration


def check_vtu_name(path: str) -> None:
    """ValueError (one line) unless `path` ends in .vtu (any case): ParaView picks its reader
    by the suffix, and the file is a VTK XML unstructured grid whatever it is called."""
    suffix = os.path.splitext(os.fspath(path))[1]
    if suffix.lower() != ".vtu":
        raise ValueError(f"export: {os.fspath(path)}: the file is a VTK XML unstructured grid; "
                         f"name it *.vtu (not {suffix!r}), the suffix ParaView reads it by")


def write_vtu(config: Configuration, path: str) -> None:
    """Write the configuration as a VTK XML unstructured grid (meshio), atomically, to a
    path ending in .vtu (else ValueError, `check_vtu_name`).

    points: model.coords padded to 3 components. Point data: "displacement" (n, 3) and
    "reaction" (n, 3) (global axes, padded with 0 in 2D; reaction nonzero at contact nodes
    only), "contact" (n,) int: position in the contact list, -1 elsewhere. Cell data per
    block of model.cells: "von_mises" (continuum) and/or "axial_force" (bars), NaN on blocks
    of the other family. A body without cells gets one "vertex" cell per node (ParaView draws
    no points without cells).
    """
    check_vtu_name(path)
    import meshio
    mdl = config.model
    n, dim = mdl.coords.shape

    def pad(a):
        out = np.zeros((len(a), 3))
        out[:, :dim] = a
        return out

    contact = np.full(n, -1, dtype=np.int64)
    contact[mdl.contact_nodes] = np.arange(mdl.m)
    blocks = [(c, np.asarray(q, dtype=np.int64)) for c, q in mdl.cells.items()]
    if not blocks:                     # a body of nodes only (kind = "matrix" without a mesh)
        blocks = [("vertex", np.arange(n, dtype=np.int64)[:, None])]
    cell_data = {name: [np.asarray(vals[c], dtype=float) if c in vals else np.full(len(q), math.nan)
                        for c, q in blocks]
                 for name, vals in config.element_values.items()}
    mesh = meshio.Mesh(pad(mdl.coords), blocks,
                       point_data={"displacement": pad(config.displacement),
                                   "reaction": pad(config.reaction), "contact": contact},
                       cell_data=cell_data)
    replace_atomic(path, lambda tmp: meshio.write(tmp, mesh, file_format="vtu"), ".vtu")
