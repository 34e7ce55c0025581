"""Meshed bodies (SPEC §3, kind = "mesh"; the element matrices: test_elements.py): Gmsh files
through meshio, normals from obstacles, the same answers as the built-ins, and
one-line errors naming the key."""
import math

import meshio
import numpy as np
import pytest
from model_cases import distorted_patch, kuhn_tets

from hpcwedge.cli import main
from hpcwedge.contact.build import build_model
from hpcwedge.contact.condense import condense
from hpcwedge.models import block2d
from hpcwedge.run.pipeline import run_scene
from hpcwedge.scene.parse import load_scene
from hpcwedge.scene.values import SceneError

TAU = math.radians(10.0)


# ----------------------------------------------------------------------------- files
def write_gmsh(path, points, body_type, body, groups=(), version="gmsh22", binary=False):
    """A Gmsh file with one body entity and one entity per named group (type, cells);
    node ids of the groups must be disjoint (each node classified on one entity)."""
    dim = 3 if body_type in ("tetra", "hexahedron") else 2
    P = np.c_[points, np.zeros(len(points))] if points.shape[1] == 2 else points
    cells, phys, geo, field = [(body_type, np.asarray(body))], [np.full(len(body), 1)], [np.full(len(body), 1)], \
        {"body": np.array([1, dim])}
    dim_tags = np.tile([dim, 1], (len(P), 1))
    for k, (name, (t, conn)) in enumerate(groups):
        conn = np.asarray(conn)
        gdim = meshio.CellBlock(t, conn).dim
        cells.append((t, conn))
        phys.append(np.full(len(conn), 10 + k))
        geo.append(np.full(len(conn), 10 + k))
        field[name] = np.array([10 + k, gdim])
        dim_tags[conn.ravel()] = [gdim, 10 + k]
    mesh = meshio.Mesh(P, cells, cell_data={"gmsh:physical": phys, "gmsh:geometrical": geo}, field_data=field,
                       point_data={"gmsh:dim_tags": dim_tags} if version == "gmsh" else {})
    meshio.write(str(path), mesh, file_format=version, binary=binary)


def _toml(v):
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return repr(float(v))


def write_scene(tmp_path, body, contact, obstacles=(), dim=2, mu="[0.65]", name="s.toml", extra=""):
    """A mesh scene: `body` and `contact` are TOML lines, `obstacles` a list of dicts."""
    text = f'name = "mesh"\ndim = {dim}\n[model]\nkind = "mesh"\n{body}\n[contact]\n{contact}\n'
    for ob in obstacles:
        text += "[[obstacle]]\n" + "".join(f"{k} = {_toml(v)}\n" for k, v in ob.items())
    text += f"[friction]\nmu = {mu}\n{extra}"
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def _num(v):
    return [float(x) for x in v]


def v_groove_obstacles(as_cone):
    """The walls of block2d/plug2d: a V of half-angle TAU from the vertical (the y axis)."""
    if as_cone:
        return [{"type": "cone", "apex": _num([0, -0.5 / math.tan(TAU)]), "axis": _num([0, 1]),
                 "half_angle_deg": 10.0}]
    c, s = math.cos(TAU), math.sin(TAU)
    return [{"type": "plane", "point": _num([-0.5, 0]), "normal": _num([c, s])},
            {"type": "plane", "point": _num([0.5, 0]), "normal": _num([c, -s])}]   # outward: sign is free


def _answers(res):
    return [(r.mu, r.n_wedged_rays, r.n_cones, sorted((tuple(c.zero_u), tuple(c.zero_r)) for c in r.cones))
            for r in res.runs]


def test_block2d_mesh_same_K_and_answers(tmp_path):
    """block2d written as Gmsh 2 (ids in block2d's contact order, two plane walls) and as
    Gmsh 4 binary (a line group: ascending ids, a V-shaped cone): the condensed K equals the
    built-in's to 1e-12 (up to the contact order), and run_scene gives the same answers."""
    ref = block2d(3, 2)
    K0, N0 = condense(ref)
    left = np.flatnonzero(np.isclose(ref.coords[:, 0], -(0.5 + ref.coords[:, 1] * math.tan(TAU))))
    right = np.flatnonzero(np.isclose(ref.coords[:, 0], 0.5 + ref.coords[:, 1] * math.tan(TAU)))
    lines = np.concatenate([np.c_[left[:-1], left[1:]], np.c_[right[:-1], right[1:]]])
    write_gmsh(tmp_path / "b2.msh", ref.coords, "quad", ref.cells["quad"], version="gmsh22")
    write_gmsh(tmp_path / "b4.msh", ref.coords, "quad", ref.cells["quad"], [("walls", ("line", lines))],
               version="gmsh", binary=True)
    s2 = write_scene(tmp_path, 'file = "b2.msh"\nE = 1.0\nnu = 0.3\nthickness = 1.0',
                     f"nodes = {ref.contact_nodes.tolist()}", v_groove_obstacles(False), name="s2.toml")
    s4 = write_scene(tmp_path, 'file = "b4.msh"', 'group = "walls"', v_groove_obstacles(True), name="s4.toml")
    m2 = build_model(load_scene(s2))
    np.testing.assert_allclose(m2.normals, ref.normals, atol=1e-14)
    K2, N2 = condense(m2)
    assert np.abs(K2 - K0).max() <= 1e-12 * np.abs(K0).max()
    m4 = build_model(load_scene(s4))
    # contact order of the group: ascending file ids; match to the built-in's by coordinates
    xr, x4 = ref.coords[ref.contact_nodes], m4.coords[m4.contact_nodes]
    perm = np.array([int(np.argmin(np.linalg.norm(x4 - x, axis=1))) for x in xr])
    assert np.abs(x4[perm] - xr).max() < 1e-14 and sorted(perm) == list(range(ref.m))
    np.testing.assert_allclose(m4.normals[perm], ref.normals, atol=1e-14)
    K4, _ = condense(m4)
    idx = np.concatenate([perm, ref.m + perm])
    assert np.abs(K4[np.ix_(idx, idx)] - K0).max() <= 1e-12 * np.abs(K0).max()
    # the same answers as the built-in through run_scene
    builtin = tmp_path / "builtin.toml"
    builtin.write_text('name = "b"\ndim = 2\n[model]\nkind = "block2d"\nrows = 3\n[friction]\nmu = [0.65]\n')
    r0, r2 = run_scene(load_scene(str(builtin))), run_scene(load_scene(s2))
    assert _answers(r2) == _answers(r0) and r0.runs[0].n_wedged_rays == 244
    assert math.isclose(r2.mu_c, r0.mu_c, rel_tol=1e-9) and math.isclose(r2.mu_c, math.tan(TAU), rel_tol=1e-9)
    for a, b in zip(r0.runs[0].cones, r2.runs[0].cones):
        assert math.isclose(a.mu_c, b.mu_c, rel_tol=1e-9)


def test_triangles_and_mixed_cells(tmp_path):
    """block2d's quads split into triangles, mixed with quads: still a free body wedged at
    tan(taper); a group of vertices."""
    ref = block2d(3, 2)
    Q = ref.cells["quad"]
    tri = np.concatenate([Q[::2][:, [0, 1, 2]], Q[::2][:, [0, 2, 3]]])
    P = np.c_[ref.coords, np.zeros(len(ref.coords))]
    mesh = meshio.Mesh(P, [("quad", Q[1::2]), ("triangle", tri), ("vertex", ref.contact_nodes[:, None])],
                       cell_data={"gmsh:physical": [np.ones(len(Q[1::2]), int), np.ones(len(tri), int),
                                                    np.full(ref.m, 2)],
                                  "gmsh:geometrical": [np.ones(len(Q[1::2]), int), np.ones(len(tri), int),
                                                       np.full(ref.m, 2)]},
                       field_data={"body": np.array([1, 2]), "contact": np.array([2, 0])})
    meshio.write(str(tmp_path / "mixed.msh"), mesh, file_format="gmsh22", binary=False)
    s = write_scene(tmp_path, 'file = "mixed.msh"', 'group = "contact"', v_groove_obstacles(True),
                    extra='[compute]\nenumerate = false\nmu_c = "global"\n')
    model = build_model(load_scene(s))
    assert set(model.cells) == {"quad", "triangle"} and model.rigid_modes.shape[1] == 3
    assert math.isclose(run_scene(load_scene(s)).mu_c, math.tan(TAU), rel_tol=1e-9)


def test_orphan_nodes_and_repeated_cells(tmp_path):
    """A point of no element (first in the file) is dropped and a cell listed twice (Gmsh 2
    repeats an element once per physical group) counts once: the condensed K is block2d's."""
    ref = block2d(2, 2)
    P = np.r_[[[9.0, 9.0, 0.0]], np.c_[ref.coords, np.zeros(len(ref.coords))]]
    Q = ref.cells["quad"] + 1
    tags = [np.full(len(Q), 1), np.full(len(Q), 2)]
    meshio.write(str(tmp_path / "o.msh"), meshio.Mesh(P, [("quad", Q), ("quad", Q)],
                 cell_data={"gmsh:physical": tags, "gmsh:geometrical": [np.ones(len(Q), int)] * 2},
                 field_data={"a": np.array([1, 2]), "b": np.array([2, 2])}), file_format="gmsh22")
    s = write_scene(tmp_path, 'file = "o.msh"', f"nodes = {(ref.contact_nodes + 1).tolist()}", v_groove_obstacles(True))
    m = build_model(load_scene(s))
    assert m.coords.shape == ref.coords.shape and len(m.cells["quad"]) == len(Q)
    K0, K1 = condense(ref)[0], condense(m)[0]
    assert np.abs(K1 - K0).max() <= 1e-12 * np.abs(K0).max()


MSH41_TWO_GROUPS = """$MeshFormat
4.1 0 8
$EndMeshFormat
$PhysicalNames
3
1 1 "bottom"
1 2 "contact"
2 3 "body"
$EndPhysicalNames
$Entities
0 1 1 0
1 0 0 0 1 0 0 2 1 2 0
1 0 0 0 1 1 0 1 3 0
$EndEntities
$Nodes
2 4 1 4
1 1 0 2
1
2
0 0 0
1 0 0
2 1 0 2
3
4
1 1 0
0 1 0
$EndNodes
$Elements
2 3 1 3
1 1 1 1
1 1 2
2 1 2 2
2 1 2 3
3 1 3 4
$EndElements
"""


def test_groups_from_every_source(tmp_path):
    """Gmsh 4: a curve in two physical groups is in both (meshio's cell sets; its
    gmsh:physical keeps only the first); Abaqus node sets (meshio point sets)."""
    from hpcwedge.models.mesh import read_mesh
    (tmp_path / "two.msh").write_text(MSH41_TWO_GROUPS)
    m = read_mesh(str(tmp_path / "two.msh"), 2)
    assert m.cells["triangle"].tolist() == [[0, 1, 2], [0, 2, 3]]
    assert {g: v.tolist() for g, v in m.groups.items()} == {"bottom": [0, 1], "contact": [0, 1], "body": [0, 1, 2, 3]}
    X, C, _, _ = distorted_patch("quad")
    meshio.write(str(tmp_path / "p.inp"), meshio.Mesh(np.c_[X, np.zeros(len(X))], [("quad", C)],
                                                      point_sets={"wall": np.array([0, 3, 6])}))
    m = read_mesh(str(tmp_path / "p.inp"), 2)
    assert m.groups["wall"].tolist() == [0, 3, 6] and len(m.cells["quad"]) == 4


# ----------------------------------------------------------------------------- 3D plug
def plug_mesh(cell, n=3, levels=3):
    """A frustum of radius 0.5 + z tan(TAU), z in [0, 1]: an n x n grid mapped onto discs
    (its outer ring on the circle), `levels` levels; hexahedra or six tetrahedra per hex.
    Returns coords, cells and the contact ids: the grid's 4 corners and 4 edge midpoints of
    the bottom and top levels (on the cone)."""
    s = np.linspace(-1, 1, n)
    gx, gy = np.meshgrid(s, s, indexing="xy")
    dx, dy = gx * np.sqrt(1 - gy ** 2 / 2), gy * np.sqrt(1 - gx ** 2 / 2)
    z = np.linspace(0, 1, levels)
    r = 0.5 + z * math.tan(TAU)
    X = np.concatenate([np.c_[r[k] * dx.ravel(), r[k] * dy.ravel(), np.full(n * n, z[k])] for k in range(levels)])
    node = np.arange(levels * n * n).reshape(levels, n, n)                  # (level, j, i)
    H = np.stack([node[:-1, :-1, :-1], node[:-1, :-1, 1:], node[:-1, 1:, 1:], node[:-1, 1:, :-1],
                  node[1:, :-1, :-1], node[1:, :-1, 1:], node[1:, 1:, 1:], node[1:, 1:, :-1]], -1).reshape(-1, 8)
    ring = [(0, 0), (0, n - 1), (n - 1, n - 1), (n - 1, 0)]
    contact = np.array([node[k, j, i] for k in (0, levels - 1) for (j, i) in ring])
    return X, (H if cell == "hexahedron" else kuhn_tets(X, H)), contact


def cone_obstacle(R=np.eye(3), b=np.zeros(3)):
    return [{"type": "cone", "apex": _num(R @ [0, 0, -0.5 / math.tan(TAU)] + b), "axis": _num(R @ [0, 0, 1]),
             "half_angle_deg": 10.0}]


def _patterns(res):
    return [(r.mu, r.n_patterns, sorted(tuple(p.contact) for p in r.patterns)) for r in res.runs]


@pytest.mark.parametrize("cell", ["hexahedron", "tetra"])
def test_plug3d_mesh(tmp_path, cell):
    """A frustum in a conical hole (free body, 6 rigid modes): mu^c = tan(taper); a vertex
    group and node ids give the same model; rotating and moving the whole scene changes
    neither the patterns nor mu^c; normals are the cone's, inward and upward."""
    X, C, contact = plug_mesh(cell)
    write_gmsh(tmp_path / "p.msh", X, cell, C, [("contact", ("vertex", contact[:, None]))], version="gmsh")
    s = write_scene(tmp_path, 'file = "p.msh"\nE = 3.0\nnu = 0.25', 'group = "contact"', cone_obstacle(),
                    dim=3, mu="[0.5, 0.9]")
    model = build_model(load_scene(s))
    assert model.rigid_modes.shape[1] == 6 and model.m == 8 and set(model.cells) == {cell}
    xc = model.coords[model.contact_nodes]
    er = np.c_[xc[:, :2], np.zeros(8)] / np.linalg.norm(xc[:, :2], axis=1)[:, None]
    np.testing.assert_allclose(model.normals, -math.cos(TAU) * er + [0, 0, math.sin(TAU)], atol=1e-12)
    np.testing.assert_allclose(model.tangents[:, 0], np.cross([0, 0, 1], er), atol=1e-12)   # circumferential
    res = run_scene(load_scene(s))
    assert math.isclose(res.mu_c, math.tan(TAU), rel_tol=1e-9)
    pats = _patterns(res)
    assert pats[0][1] >= 1 and pats[1][1] > pats[0][1]
    assert all(p.mu_c >= res.mu_c * (1 - 1e-9) for r in res.runs for p in r.patterns)
    # the same body by node ids (group order = ascending ids), rotated and moved
    rng = np.random.default_rng(7)
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    R *= np.linalg.det(R)
    b = rng.normal(size=3)
    write_gmsh(tmp_path / "q.msh", X @ R.T + b, cell, C, version="gmsh22", binary=True)
    s2 = write_scene(tmp_path, 'file = "q.msh"\nE = 3.0\nnu = 0.25', f"nodes = {sorted(contact.tolist())}",
                     cone_obstacle(R, b), dim=3, mu="[0.5, 0.9]", name="q.toml")
    res2 = run_scene(load_scene(s2))
    assert math.isclose(res2.mu_c, res.mu_c, rel_tol=1e-9)
    assert _patterns(res2) == pats


def test_supports_by_group_and_ids(tmp_path):
    """Supports remove rigid modes: a roller group (dof 1) leaves 2, plus x held by ids at
    two nodes above each other, none."""
    ref = block2d(3, 2)
    top, bottom = [int(np.flatnonzero(np.isclose(ref.coords[:, 1], y) & np.isclose(ref.coords[:, 0], 0))[0])
                   for y in (1.0, 0.0)]
    write_gmsh(tmp_path / "b.msh", ref.coords, "quad", ref.cells["quad"], [("top", ("vertex", [[top]]))])
    s = write_scene(tmp_path, 'file = "b.msh"\nsupport_group = "top"\nsupport_dofs = [1]',
                    f"nodes = {ref.contact_nodes.tolist()}", v_groove_obstacles(True))
    m = build_model(load_scene(s))
    assert m.rigid_modes.shape[1] == 2 and len(m.fixed_dofs) == 1
    p = write_scene(tmp_path, f'file = "b.msh"\nsupport_group = "top"\nsupports = [[{top}, 0], [{bottom}, 0]]',
                    f"nodes = {ref.contact_nodes.tolist()}", v_groove_obstacles(True), name="p.toml")
    m = build_model(load_scene(p))
    assert m.rigid_modes.shape[1] == 0 and len(m.fixed_dofs) == 3
    assert condense(m)[1].shape[1] == 0


# ----------------------------------------------------------------------------- errors
@pytest.fixture(scope="module")
def block_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("errs")
    ref = block2d(2, 2)
    Q = ref.cells["quad"]
    write_gmsh(d / "ok.msh", ref.coords, "quad", Q, [("contact", ("vertex", ref.contact_nodes[:, None]))])
    bad = Q.copy()
    bad[3] = bad[3][::-1]                                                 # clockwise
    write_gmsh(d / "inverted.msh", ref.coords, "quad", bad)
    P = np.c_[ref.coords, np.zeros(len(ref.coords))]
    tri6 = np.c_[Q[:, :3], Q[:, :3]]                                      # nonsense, but a triangle6 block
    meshio.write(str(d / "tri6.msh"), meshio.Mesh(P, [("triangle6", tri6)]), file_format="gmsh22")
    meshio.write(str(d / "wavy.msh"), meshio.Mesh(P + [0, 0, 1] * (P[:, :1] > 0), [("quad", Q)]),
                 file_format="gmsh22")
    meshio.write(str(d / "orphan.msh"), meshio.Mesh(np.r_[P, [[5.0, 5.0, 0.0]]], [("quad", Q)]),
                 file_format="gmsh22")
    (d / "garbage.msh").write_text("$MeshFormat\nnot a mesh\n")
    return d, ref


OK_BODY = 'file = "ok.msh"'
OK_CONTACT = 'group = "contact"'


@pytest.mark.parametrize("body,contact,obstacles,key,phrase", [
    (OK_BODY, OK_CONTACT, "off", "obstacle", "from the nearest obstacle surface"),
    ('file = "inverted.msh"', "ids", "v", "model.file", "quad element 3 has a non-positive Jacobian"),
    ('file = "tri6.msh"', "ids", "v", "model.file", "unsupported cell type 'triangle6'"),
    (OK_BODY, 'group = "nope"', "v", "contact.group", "unknown group 'nope'"),
    (OK_BODY, 'group = ["contact", "body"]', "v", "contact.group", "is in both group 'contact' and group 'body'"),
    (OK_BODY, 'group = ["contact", "contact"]', "v", "contact.group", "listed twice"),
    (OK_BODY, "nodes = [0, 3, 0]", "v", "contact.nodes", "duplicate node 0"),
    (OK_BODY, "nodes = [0, 2]\nnormals = [[1.0, 0.0], [0.0, 0.0]]", None, "contact.normals",
     "zero normal at contact node 1"),
    (OK_BODY, OK_CONTACT, "zero", "obstacle[0].normal", "zero vector"),
    (OK_BODY, OK_CONTACT, "apex", "obstacle[0]", "apex"),
    (OK_BODY, "nodes = [0, 99]", "v", "contact.nodes", "node 99 does not exist"),
    ('file = "orphan.msh"', "nodes = [0, 9]", "v", "contact.nodes", "belongs to no element"),
    ('file = "missing.msh"', OK_CONTACT, "v", "model.file", "not found"),
    ('file = "garbage.msh"', OK_CONTACT, "v", "model.file", "cannot read"),
    ('file = "wavy.msh"', OK_CONTACT, "v", "model.file", "not planar"),
    (OK_BODY + "\nnu = 0.5", OK_CONTACT, "v", "model.nu", "(-1, 0.5)"),
    (OK_BODY + "\nsupport_group = \"contact\"", OK_CONTACT, "v", "model.support_group", "contact DOFs must be free"),
    (OK_BODY + "\ncolour = 1", OK_CONTACT, "v", "model.colour", "unknown key"),
    (OK_BODY, OK_CONTACT + "\nnodes = [0]", "v", "contact.group / contact.nodes", "exactly one"),
    (OK_BODY, OK_CONTACT + "\nnormals = [[1.0, 0.0]]", "v", "contact.normals / obstacle", "exactly one"),
    (OK_BODY, OK_CONTACT, "sphere", "obstacle[0].type", "\"plane\" or \"cone\""),
])
def test_errors_name_the_key(block_files, body, contact, obstacles, key, phrase):
    d, ref = block_files
    contact = contact.replace("ids", f"nodes = {ref.contact_nodes.tolist()}")
    obs = {"v": v_groove_obstacles(True), None: [],
           "off": [{"type": "plane", "point": _num([-0.5, 0]), "normal": _num([1, 0])}],
           "zero": [{"type": "plane", "point": _num([-0.5, 0]), "normal": _num([0, 0])}],
           "apex": [{"type": "cone", "apex": _num(ref.coords[0]), "axis": _num([0, 1]), "half_angle_deg": 45.0}]
           + v_groove_obstacles(True),
           "sphere": [{"type": "sphere", "centre": _num([0, 0])}]}[obstacles]
    s = write_scene(d, body, contact, obs)
    with pytest.raises(SceneError) as e:
        build_model(load_scene(s))
    msg = str(e.value)
    assert msg.startswith(key) and phrase in msg and "\n" not in msg, msg


def test_obstacle_forms_and_tolerance(block_files):
    """contact.obstacle (inline tables) = [[obstacle]]; contact.tolerance widens the band;
    obstacles are for mesh scenes only, and given once."""
    d, ref = block_files
    a = build_model(load_scene(write_scene(d, OK_BODY, OK_CONTACT, v_groove_obstacles(True))))
    (d / "inline.toml").write_text(
        'name = "i"\ndim = 2\n[model]\nkind = "mesh"\nfile = "ok.msh"\n[contact]\ngroup = "contact"\n'
        f'obstacle = [{{type = "cone", apex = [0.0, {-0.5 / math.tan(TAU)!r}], axis = [0.0, 1.0], '
        'half_angle_deg = 10.0}]\n[friction]\nmu = 1.0\n')
    b = build_model(load_scene(str(d / "inline.toml")))
    np.testing.assert_array_equal(a.normals, b.normals)
    off = [{"type": "plane", "point": _num([-0.5, 0]), "normal": _num([1, 0])}]
    m = build_model(load_scene(write_scene(d, OK_BODY, OK_CONTACT + "\ntolerance = 10", off)))
    assert np.all(np.abs(m.normals[:, 0]) == 1.0)
    with pytest.raises(SceneError, match=r'^obstacle: obstacle surfaces are for kind = "mesh"'):
        load_scene(_builtin_with_obstacle(d))
    text = (d / "inline.toml").read_text().replace("[friction]", "[[obstacle]]\ntype = \"plane\"\n"
                                                  "point = [0.0, 0.0]\nnormal = [0.0, 1.0]\n[friction]")
    (d / "both.toml").write_text(text)
    with pytest.raises(SceneError, match=r"^obstacle: give \[\[obstacle\]\] tables or contact.obstacle, not both"):
        load_scene(str(d / "both.toml"))


def _builtin_with_obstacle(d):
    p = d / "builtin_obstacle.toml"
    p.write_text('name = "b"\ndim = 2\n[model]\nkind = "plug2d"\n[[obstacle]]\ntype = "plane"\n'
                 'point = [0.0, 0.0]\nnormal = [0.0, 1.0]\n[friction]\nmu = 1.0\n')
    return str(p)


def test_cli_bad_mesh_exit_2_nothing_written(block_files, tmp_path, capsys):
    d, ref = block_files
    s = write_scene(d, 'file = "inverted.msh"', f"nodes = {ref.contact_nodes.tolist()}", v_groove_obstacles(True),
                    name="cli.toml")
    out = tmp_path / "r.h5"
    assert main(["run", s, "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert "model.file: quad element 3 has a non-positive Jacobian" in err and not out.exists()


def test_boundary_nodes_of_each_cell_type():
    """models.mesh.boundary_nodes: on a 2 x 2 grid of quads (and of triangles, each quad
    split) and a 2 x 2 x 2 grid of hexahedra (and of tetrahedra, each cube in six), every
    node but the centre is on the boundary."""
    from hpcwedge.models.mesh import boundary_nodes
    g2 = np.arange(9).reshape(3, 3)
    quads = np.array([[g2[i, j], g2[i, j + 1], g2[i + 1, j + 1], g2[i + 1, j]] for i in range(2) for j in range(2)])
    tris = np.vstack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    g3 = np.arange(27).reshape(3, 3, 3)
    hexes = np.array([[g3[i, j, k], g3[i, j, k + 1], g3[i, j + 1, k + 1], g3[i, j + 1, k],
                       g3[i + 1, j, k], g3[i + 1, j, k + 1], g3[i + 1, j + 1, k + 1], g3[i + 1, j + 1, k]]
                      for i in range(2) for j in range(2) for k in range(2)])
    tets = np.vstack([h[[0, p, q, 6]] for h in hexes for p, q in ((1, 2), (2, 3), (3, 7), (7, 4), (4, 5), (5, 1))])
    for n, cells, centre in ((9, {"quad": quads}, 4), (9, {"triangle": tris}, 4),
                             (27, {"hexahedron": hexes}, 13), (27, {"tetra": tets}, 13)):
        b = boundary_nodes(n, cells)
        assert not b[centre] and b.sum() == n - 1, cells.keys()


def test_given_normals_and_nodes_checked_against_the_body(tmp_path):
    """contact.nodes with contact.normals on block2d's mesh: its own inward normals are taken;
    one flipped out of the body, or an interior node, is a one-line error naming the key
    (before: accepted, and the flipped normal gave mu^c none_at_any_mu, exit 0)."""
    ref = block2d(3, 2)
    write_gmsh(tmp_path / "b.msh", ref.coords, "quad", ref.cells["quad"])
    nodes = ref.contact_nodes.tolist()
    good = write_scene(tmp_path, 'file = "b.msh"', f"nodes = {nodes}\nnormals = {ref.normals.tolist()}",
                       name="good.toml")
    assert np.allclose(build_model(load_scene(good)).normals, ref.normals)
    flipped = ref.normals.copy()
    flipped[2] *= -1
    bad = write_scene(tmp_path, 'file = "b.msh"', f"nodes = {nodes}\nnormals = {flipped.tolist()}", name="flip.toml")
    with pytest.raises(SceneError, match=r"^contact.normals\[2\]: points out of the body"):
        build_model(load_scene(bad))
    from hpcwedge.models.mesh import boundary_nodes
    inner = int(np.flatnonzero(~boundary_nodes(len(ref.coords), ref.cells))[0])
    inside = write_scene(tmp_path, 'file = "b.msh"',
                         f"nodes = {nodes[:-1] + [inner]}\nnormals = {ref.normals.tolist()}", name="in.toml")
    with pytest.raises(SceneError, match=rf"^contact.nodes: node {inner} lies inside the body"):
        build_model(load_scene(inside))
