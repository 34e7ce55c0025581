#!/usr/bin/env python3
"""Build the Gmsh example bodies shipped in scripts/examples/ (needs the `gmsh` package:
``pip install .[examples]``; `make demo` and the tests use the committed files).

- cork2d.msh / cork2d.toml: a cork profile (trapezoid with a rounded top) in a neck whose
  walls lean TAPER_2D_DEG from the vertical; plane-stress triangles; the two slanted sides
  are the physical curve "contact", each meshed with SIDE_NODES_2D equally spaced nodes
  (m = 2 * SIDE_NODES_2D), the interior finer; the body is the physical surface "cork".
- plug3d.msh / plug3d.toml: a frustum plug in a conical hole of half-angle TAPER_3D_DEG;
  tetrahedra; RINGS_3D rings of RING_NODES_3D points embedded in the conical surface
  (staggered by half a pitch) are the physical point group "contact"; the body is the
  physical volume "plug".

Both are free bodies (no supports) whose contact nodes lie exactly on the obstacle, so
the global mu^c should come out as tan(taper) (the rigid-translation bound of a V / cone).
The script also writes examples.json: the structure of each mesh (`mesh_summary`) and the
counts of a run of each scene (`run_counts`), which tests/test_examples.py checks.

    PYTHONPATH=. python scripts/make_examples.py [--out DIR] [--no-run]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLES = os.path.join(ROOT, "scripts", "examples")
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)         # hpcwedge from this checkout (imported lazily: gmsh-free import)

TAPER_2D_DEG = 8.0      # neck walls from the vertical
BOTTOM_HALF_WIDTH = 0.5
HEIGHT_2D = 1.2
SIDE_NODES_2D = 5       # nodes per slanted side (m = 10)
LC_2D = 0.06            # interior element size

TAPER_3D_DEG = 12.0     # cone half-angle
BOTTOM_RADIUS = 0.5
HEIGHT_3D = 1.0
RINGS_3D = (0.25, 0.75)  # ring heights as fractions of HEIGHT_3D
RING_NODES_3D = 5        # points per ring (m = 10)
LC_3D = 0.2

SCENES = {
    "cork2d": f'''# A cork profile in a tapered neck (scripts/make_examples.py): walls {TAPER_2D_DEG:g} deg from
# the vertical, {SIDE_NODES_2D} contact nodes per side (m = {2 * SIDE_NODES_2D}); expected global mu^c = tan {TAPER_2D_DEG:g} deg.
name = "cork2d"
dim = 2
[model]
kind = "mesh"
file = "cork2d.msh"
E = 1.0
nu = 0.3
thickness = 1.0
[contact]
group = "contact"
[[obstacle]]
type = "cone"
apex = [0.0, {-BOTTOM_HALF_WIDTH / math.tan(math.radians(TAPER_2D_DEG))!r}]
axis = [0.0, 1.0]
half_angle_deg = {TAPER_2D_DEG!r}
[friction]
mu = [0.65]
[compute]
enumerate = true
mu_c = "cones"
''',
    "plug3d": f'''# A frustum plug in a conical hole (scripts/make_examples.py): half-angle {TAPER_3D_DEG:g} deg,
# {len(RINGS_3D)} rings of {RING_NODES_3D} contact points (m = {len(RINGS_3D) * RING_NODES_3D}); expected global mu^c = tan {TAPER_3D_DEG:g} deg.
name = "plug3d-gmsh"
dim = 3
[model]
kind = "mesh"
file = "plug3d.msh"
E = 1.0
nu = 0.3
[contact]
group = "contact"
[[obstacle]]
type = "cone"
apex = [0.0, 0.0, {-BOTTOM_RADIUS / math.tan(math.radians(TAPER_3D_DEG))!r}]
axis = [0.0, 0.0, 1.0]
half_angle_deg = {TAPER_3D_DEG!r}
[friction]
mu = [0.5, 0.8]
[compute]
enumerate = true
mu_c = "cones"
''',
}


def _start(name: str):
    """A fresh gmsh model, quiet, writing Gmsh 4.1 ASCII."""
    import gmsh
    if not gmsh.isInitialized():
        gmsh.initialize(["gmsh", "-v", "0"], readConfigFiles=False)
    gmsh.clear()
    gmsh.model.add(name)
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.option.setNumber("Mesh.Binary", 0)
    gmsh.option.setNumber("Mesh.RandomSeed", 1)
    return gmsh


def build_cork2d(path: str) -> None:
    """Write the 2D cork (see the module docstring) to `path` (.msh)."""
    gmsh = _start("cork2d")
    geo = gmsh.model.geo
    a, h = BOTTOM_HALF_WIDTH, HEIGHT_2D
    b = a + h * math.tan(math.radians(TAPER_2D_DEG))       # half-width at the top of the sides
    p = [geo.addPoint(-a, 0, 0, LC_2D), geo.addPoint(a, 0, 0, LC_2D),
         geo.addPoint(b, h, 0, LC_2D), geo.addPoint(-b, h, 0, LC_2D)]
    centre = geo.addPoint(0, h - b, 0, LC_2D)                 # the top: a 90-degree arc
    bottom, right = geo.addLine(p[0], p[1]), geo.addLine(p[1], p[2])
    top, left = geo.addCircleArc(p[2], centre, p[3]), geo.addLine(p[3], p[0])
    surface = geo.addPlaneSurface([geo.addCurveLoop([bottom, right, top, left])])
    for c in (right, left):
        geo.mesh.setTransfiniteCurve(c, SIDE_NODES_2D)
    geo.synchronize()
    gmsh.model.addPhysicalGroup(1, [right, left], name="contact")
    gmsh.model.addPhysicalGroup(2, [surface], name="cork")
    gmsh.option.setNumber("Mesh.MeshSizeMax", LC_2D)        # finer inside than along the sides
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.model.mesh.generate(2)
    gmsh.write(path)
    gmsh.finalize()


def build_plug3d(path: str) -> None:
    """Write the 3D plug (see the module docstring) to `path` (.msh)."""
    gmsh = _start("plug3d")
    occ = gmsh.model.occ
    tan = math.tan(math.radians(TAPER_3D_DEG))
    volume = occ.addCone(0, 0, 0, 0, 0, HEIGHT_3D, BOTTOM_RADIUS, BOTTOM_RADIUS + HEIGHT_3D * tan)
    points = []
    for k, frac in enumerate(RINGS_3D):
        z = frac * HEIGHT_3D
        r = BOTTOM_RADIUS + z * tan
        for j in range(RING_NODES_3D):
            phi = 2 * math.pi * (j + 0.5 * k) / RING_NODES_3D + 0.1   # off the surface's seam
            points.append(occ.addPoint(r * math.cos(phi), r * math.sin(phi), z))
    occ.synchronize()
    lateral = [s for _, s in gmsh.model.getBoundary([(3, volume)], oriented=False)
               if gmsh.model.getType(2, s) == "Cone"]
    if len(lateral) != 1:
        raise RuntimeError(f"expected one conical face, got {lateral}")
    gmsh.model.mesh.embed(0, points, 2, lateral[0])
    gmsh.model.addPhysicalGroup(0, points, name="contact")
    gmsh.model.addPhysicalGroup(3, [volume], name="plug")
    gmsh.option.setNumber("Mesh.MeshSizeMin", LC_3D)
    gmsh.option.setNumber("Mesh.MeshSizeMax", LC_3D)
    gmsh.model.mesh.generate(3)
    gmsh.write(path)
    gmsh.finalize()


BUILDERS = {"cork2d": (2, build_cork2d), "plug3d": (3, build_plug3d)}


def mesh_summary(path: str, dim: int) -> dict:
    """The structure of an example mesh as hpcwedge reads it: node count, body cells per
    type, group names, and the contact group's size and node coordinates (rounded to 1e-9)."""
    from hpcwedge.models.mesh import group_nodes, read_mesh
    mesh = read_mesh(path, dim)
    contact = group_nodes(mesh, "contact", "contact.group")
    return {"dim": dim, "nodes": int(len(mesh.points)),
            "cells": {k: int(len(v)) for k, v in sorted(mesh.cells.items())},
            "groups": sorted(mesh.groups), "m": int(len(contact)),
            "contact_coords": sorted([round(float(x), 9) for x in mesh.points[i, :dim]] for i in contact)}


def run_counts(scene_path: str) -> dict:
    """Run a scene in process and return what the example test compares: m, the global
    mu^c and per mu the wedged / trivial ray, cone and pattern counts."""
    from hpcwedge.run.pipeline import run_scene
    from hpcwedge.scene.parse import load_scene
    res = run_scene(load_scene(scene_path))
    return {"m": int(res.m), "mu_c": res.mu_c,
            "runs": [{"mu": r.mu, "n_wedged_rays": r.n_wedged_rays, "n_trivial_rays": r.n_trivial_rays,
                      "n_cones": r.n_cones, "n_patterns": r.n_patterns} for r in res.runs]}


def build(out: str, names=tuple(BUILDERS)) -> None:
    """Write the .msh and .toml of the named examples into `out`."""
    os.makedirs(out, exist_ok=True)
    for name in names:
        BUILDERS[name][1](os.path.join(out, name + ".msh"))
        with open(os.path.join(out, name + ".toml"), "w") as f:
            f.write(SCENES[name])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=EXAMPLES)
    ap.add_argument("--no-run", action="store_true", help="only the meshes and scenes (examples.json untouched)")
    args = ap.parse_args()
    build(args.out)
    if args.no_run:
        return 0
    record = {name: mesh_summary(os.path.join(args.out, name + ".msh"), dim) for name, (dim, _) in BUILDERS.items()}
    for name in record:
        record[name]["result"] = run_counts(os.path.join(args.out, name + ".toml"))
    with open(os.path.join(args.out, "examples.json"), "w") as f:
        json.dump(record, f, indent=1)
        f.write("\n")
    for name, rec in record.items():
        size = os.path.getsize(os.path.join(args.out, name + ".msh"))
        print(f"{name}: {rec['nodes']} nodes, cells {rec['cells']}, m = {rec['m']}, {size / 1024:.0f} KiB"
              + (f", {rec['result']}" if "result" in rec else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
