"""Whole-body wedged configurations: every node's displacement, the contact reactions and
the element stresses of one item of a result (export.write_vtu writes one as a VTU file).

A result stores the contact DOFs only (SPEC §1: local frames, block ordering
[n_1..n_m, t_1..t_m(, t2_1..t2_m)]). One configuration (u_local, r_local), each (dim*m,),
is taken from an item of a run:

    ray J       2D: wedged ray J, [u, r] as stored (sum r_n = 1).
    cone J      2D: the mean of the cone's wedged rays (each sum r_n = 1, so the mean too):
                the cone's rays are pairwise cross-complementary, so their sum is a wedged
                configuration of the cone.
    pattern J   one point of the pattern's feasible set at the run's mu:
                feasibility.decide(pattern_rows(...)) (3D: the SOCP; 2D: the LP) gives x,
                and u = U x, r = R x (problem.parametrize), scaled to sum r_n = 1.

and extended to the body by the static condensation read backwards (`whole_body`):

    u_c = T^T u_local            global contact DOFs, node-major (T = model.local_map(), orthogonal)
    u_i = -K_ii^-1 K_ic u_c      condense.interior_response (the factorisation `condense` uses)
    u = 0 at supported DOFs
    f   = T^T r_local at the contact DOFs, 0 elsewhere: the obstacle's force on the body

so that K u = f at every free DOF (the supports take K u at theirs). With contact patches
(model.tie, models/patch.py) the reduced u_i includes the feet's rotations, u = Q u_red
(Q = model.tie.T), and the equilibrium is Q^T (K u - f) = 0: the feet press on their slave
nodes (K u is their pressure there). The amplitude is that
of the normalised item (sum r_n = 1, in force units; displacements in length units); any
positive multiple is the same wedged configuration.

Element values (`element_values`): von Mises stress at the centroid of every continuum
element (plane stress in 2D), axial force (tension > 0) of every bar.
"""
from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass

import numpy as np

from hpcwedge.errors import UserError
from hpcwedge.models.record import Model
from hpcwedge.nodesets import to_mask
from hpcwedge.results.record import StoredModel

#: cell-data names by cell family, in the VTU and in Configuration.element_values
VON_MISES, AXIAL_FORCE = "von_mises", "axial_force"
#: the stored /model must agree with the rebuilt one to this relative tolerance
MODEL_MATCH_RTOL = 1e-12


class ConfigurationError(UserError):
    """A configuration cannot be made from this result / item: one line, for exit status 2."""


@dataclass(frozen=True)
class Configuration:
    """One wedged configuration of the whole body.

    model:          the body (hpcwedge.models.record.Model).
    u_local, r_local: (dim*m,) contact displacement and reaction, local frames, block ordering.
    displacement:   (n_nodes, dim) every node, global axes.
    reaction:       (n_nodes, dim) obstacle force on the body, global axes; zero off contact.
    element_values: {VON_MISES or AXIAL_FORCE: {cell type: (ne,)}} for the blocks of model.cells.
    label:          what was taken, e.g. "run 0 (mu = 0.65), wedged ray 3 of 44".
    """

    model: Model
    u_local: np.ndarray
    r_local: np.ndarray
    displacement: np.ndarray
    reaction: np.ndarray
    element_values: dict
    label: str = ""


# --------------------------------------------------------------------------- recovery

def to_global(model: Model, v_local: np.ndarray) -> np.ndarray:
    """(dim*m,) local block-ordered contact vector -> (m, dim) global vectors per contact node."""
    v = np.asarray(v_local, dtype=float)
    if v.shape != (model.dim * model.m,):
        raise ValueError(f"configuration: expected a local contact vector of size dim*m = "
                         f"{model.dim * model.m}, got shape {v.shape}")
    return (model.local_map().T @ v).reshape(model.m, model.dim)


def whole_body(model: Model, u_local: np.ndarray, r_local: np.ndarray, label: str = "",
               solver: str | None = None) -> Configuration:
    """The Configuration of `model` with contact displacement u_local and reaction r_local
    (each (dim*m,), local frames, block ordering): see the module doc for the recovery."""
    from hpcwedge.contact.condense import interior_response, split_dofs
    n, dim = model.coords.shape
    uc = to_global(model, u_local).ravel()
    q = model.tie.n_rotations if model.tie is not None else 0
    u = np.zeros(n * dim + q)
    u[model.contact_dofs()] = uc
    u[split_dofs(model).interior] = interior_response(model, uc, solver=solver)
    if model.tie is not None:
        u = model.tie.T @ u                  # slaves of the contact patches from their feet
    f = np.zeros((n, dim))
    f[model.contact_nodes] = to_global(model, r_local)
    U = u.reshape(n, dim)
    return Configuration(model=model, u_local=np.asarray(u_local, dtype=float),
                         r_local=np.asarray(r_local, dtype=float), displacement=U, reaction=f,
                         element_values=element_values(model, U), label=label)


def element_values(model: Model, displacement: np.ndarray) -> dict:
    """{VON_MISES: {continuum cell type: (ne,)}, AXIAL_FORCE: {"line": (nb,)}} (families that
    the model has), from the nodal displacement (n_nodes, dim) and model.material. Empty when
    the model carries no material (then there is nothing to recover per element)."""
    from hpcwedge.models.continuum import continuum_von_mises
    from hpcwedge.models.truss import bar_forces
    out: dict = {}
    mat = model.material
    if "line" in model.cells and "EA" in mat:
        out[AXIAL_FORCE] = {"line": bar_forces(model.coords, model.cells["line"], mat["EA"], displacement)}
    solid = {c: q for c, q in model.cells.items() if c != "line"}
    if solid and "E" in mat:
        out[VON_MISES] = continuum_von_mises(model.coords, solid, displacement, mat)
    return out


# --------------------------------------------------------------------------- from a result

def load_configuration(path: str, run: int = -1, ray: int | None = None, cone: int | None = None,
                       pattern: int | None = None, solver: str | None = None) -> Configuration:
    """The Configuration of one item (exactly one of ray, cone, pattern) of run `run` of the
    result file `path` (indices 0-based, Python-style negatives allowed), on the body rebuilt
    from the scene text stored in the result (`rebuild_model`).

    ConfigurationError (one line) for a missing file, a result of a `stiffness` scene (no
    body), a run or item index out of range, a run without that kind of item, or a pattern
    whose feasibility point the solvers cannot give.
    """
    from hpcwedge.files import FileError
    from hpcwedge.results.hdf5 import (
        RangeError,
        index,
        index_range,
        open_result,
        read_items,
        read_model,
        read_rays,
        read_run,
        stored_scene,
    )
    chosen = [(k, v) for k, v in (("ray", ray), ("cone", cone), ("pattern", pattern)) if v is not None]
    if len(chosen) != 1:
        raise ConfigurationError("give exactly one of ray, cone, pattern")
    what, j = chosen[0]
    try:
        with open_result(path, passthrough=(ConfigurationError,)) as f:
            dim, m = int(f.attrs["dim"]), int(f.attrs["m"])
            try:
                k, _, g = read_run(f, run)
            except RangeError as e:
                raise ConfigurationError(str(e)) from None
            mu = float(g.attrs["mu"])
            rays = read_rays(g, 2 * dim * m)
            n_rays = 0 if rays is None else len(rays)
            cones, patterns = read_items(g, "cones", n_rays, m), read_items(g, "patterns", n_rays, m)
            text, scene_dir, inputs = stored_scene(f)
            stored = read_model(f)
    except FileError as e:
        raise ConfigurationError(str(e)) from None
    items = {"ray": rays, "cone": cones, "pattern": patterns}[what]
    head = f"run {k} (mu = {mu:.6g})"
    noun = "wedged ray" if what == "ray" else what
    if items is None:
        why = {"ray": "wedged rays are 2D results of compute.enumerate = true or \"rays\"",
               "cone": "cones are 2D results of compute.enumerate = true",
               "pattern": "sign patterns are 3D results, or 2D with compute.enumerate = \"patterns\""}[what]
        raise ConfigurationError(f"{head} has no {noun}s ({why})")
    i = index(j, len(items))
    if i is None:
        raise ConfigurationError(f"{what} {j} out of range ({head} has {len(items)} {noun}(s): "
                                 f"{index_range(len(items))})")
    scene, model = rebuild_model(path, text, scene_dir, stored, inputs)
    n = dim * m
    label = f"{head}, {noun} {i} of {len(items)}"
    if what == "ray":
        u, r = rays[i, :n], rays[i, n:]
    elif what == "cone":
        members = items[i].rays
        if not members:
            raise ConfigurationError(f"cone {i} of {head} has no wedged ray")
        v = rays[members].mean(axis=0)
        u, r = v[:n], v[n:]
        label += f" (mean of its {len(members)} wedged ray(s))"
    else:
        u, r = pattern_point(scene, model, items[i].contact, mu)
        label += f" (contact {items[i].contact}; a feasible point)"
    try:
        return whole_body(model, u, r, label=label, solver=solver)
    except ValueError as e:
        raise ConfigurationError(str(e).splitlines()[0]) from None


def pattern_point(scene, model: Model, contact: list[int], mu: float) -> tuple[np.ndarray, np.ndarray]:
    """(u_local, r_local) of one solution of the sign pattern (C = contact, G = the other nodes)
    at mu, normalised to sum r_n = 1: feasibility.decide on pattern_rows of the parametrisation."""
    from hpcwedge.contact.build import contact_problem, unscale_u
    from hpcwedge.contact.problem import parametrize
    from hpcwedge.solvers.feasibility import decide
    from hpcwedge.solvers.rows import Status, pattern_rows
    problem = contact_problem(scene, model)
    param = parametrize(problem)
    m = problem.m
    zero_u = to_mask(contact, m)
    dec = decide(pattern_rows(param, m, zero_u, ~zero_u), mu)
    status, x = dec.status, dec.x
    if status != Status.FEASIBLE:
        raise ConfigurationError(f"pattern with contact {list(contact)} at mu = {mu:.6g}: the solvers "
                                 f"return {status}, no configuration to export")
    u, r = unscale_u(param.U @ x, scene), param.R @ x      # K is rescaled (build.stiffness_exponent)
    s = r[:m].sum()
    return u / s, r / s


def rebuild_model(path: str, text: str, scene_dir: str | None, stored: StoredModel | None,
                  inputs: dict | None = None):
    """(Scene, Model) of the result file `path`, from its stored scene text and folder and
    input digests (results.stored_scene) and its /model (results.read_model; None: none).

    Files named in the scene (a mesh's model.file) are relative to the scene's folder, which
    the result records (attribute scene_dir); if the file is not there, the result's own
    folder is tried. The rebuilt model must match the result's /model (coordinates and
    contact nodes), and the files the scene names must have the digests the result recorded
    (`inputs`, Scene.input_digests), else ConfigurationError (the mesh file changed since the run).
    """
    from hpcwedge.contact.build import build_model
    from hpcwedge.scene.parse import parse_scene
    from hpcwedge.scene.values import SceneError
    result_dir = os.path.dirname(os.path.abspath(path))
    try:
        data = tomllib.loads(text)
        table = data.get("model") if isinstance(data.get("model"), dict) else {}
        kind = table.get("kind")
        if kind == "stiffness":
            raise ConfigurationError("the scene is of kind \"stiffness\" (a condensed K only): "
                                     "there is no body to export")
        dirs = [d for d in (scene_dir, result_dir) if d]
        base = dirs[0]
        name = table.get("file")
        if isinstance(name, str):
            found = [d for d in dirs if os.path.exists(os.path.join(d, name))]
            if not found:
                raise ConfigurationError(f"model.file: {name} not found in the scene's folder or the "
                                         f"result's ({' or '.join(dict.fromkeys(dirs))})")
            base = found[0]
        scene = parse_scene(data, text=text, base_dir=base)
        changed = [k for k, v in (inputs or {}).items() if scene.input_digests.get(k) != v]
        if changed:
            raise ConfigurationError(f"{changed[0]} changed since the result was written (its SHA-256 "
                                     f"differs from the one the result recorded)")
        model = build_model(scene)
    except (SceneError, tomllib.TOMLDecodeError) as e:
        raise ConfigurationError(f"cannot rebuild the body from the stored scene: {str(e).splitlines()[0]}") from None
    if stored is not None:
        X, c = np.asarray(stored.coords, float), np.asarray(stored.contact_nodes)
        scale = max(float(np.abs(X).max(initial=0.0)), 1e-300)
        if (X.shape != model.coords.shape or not np.array_equal(c, model.contact_nodes)
                or np.abs(X - model.coords).max() > MODEL_MATCH_RTOL * scale):
            raise ConfigurationError("the body rebuilt from the stored scene differs from the result's "
                                     "/model (was the mesh file changed since the run?)")
    return scene, model
