"""Scenes made in Python: a dict, a built-in's parameters, a condensed stiffness, a truss.

Every one becomes a scene table that goes through the one validator (parse.parse_scene), so
every check, default and error (a SceneError naming the key) is the parser's; the table is
kept as TOML text (Scene.text): its hash identifies the scene, and a result file stores it.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from hpcwedge.scene.parse import Scene
from hpcwedge.scene.tables import DEFAULT_MU

# --------------------------------------------------------------------------- scenes

def scene_from_dict(data: Mapping, *, base_dir: str | None = None) -> Scene:
    """The Scene of a scene table given as a dict (the TOML file's structure, SPEC §3).

    Parameters
    ----------
    data : Mapping
        ``{"name", "dim", "model": {...}, "friction": {"mu": ...}, "compute": {...}, ...}``.
        Values may be numpy arrays and scalars and tuples (stored as lists); a key whose
        value is None is left out (its default applies).
    base_dir : str, optional
        The folder that relative file names (``model.file``) are relative to; default: the
        current directory at the time of the call.

    Returns
    -------
    Scene
        Validated by scene.parse_scene; ``Scene.text`` is the table as TOML.

    Raises
    ------
    SceneError
        One line naming the key and the reason.

    Examples
    --------
    >>> s = scene_from_dict({"name": "v", "dim": 2, "model": {"kind": "vgroove_bar"},
    ...                      "friction": {"mu": [0.5, 1.0]}})
    >>> s.mu, s.kind
    ((0.5, 1.0), 'vgroove_bar')
    >>> scene_from_dict({"name": "v", "dim": 2, "model": {"kind": "vgroove_bar"},
    ...                  "friction": {"mu": -1}})
    Traceback (most recent call last):
    hpcwedge.scene.values.SceneError: friction.mu: every value must be a finite number > 0, got -1
    """
    return Scene.from_dict(data, base_dir=base_dir)



def builtin_scene(kind: str, *, mu: float | Sequence[float] = DEFAULT_MU, name: str | None = None,
                  **params: Any) -> Scene:
    """The scene of a built-in model (SPEC §6).

    Parameters
    ----------
    kind : str
        ``"plug2d"``, ``"plug3d"``, ``"block2d"`` or ``"vgroove_bar"``.
    mu : float or sequence of float
        The friction coefficient(s) to enumerate at (friction.mu).
    name : str, optional
        The scene's name (default: the kind).
    **params
        The model's parameters (``rows``, ``taper_deg``...) and any [compute] or [run]
        option (``mu_c="global"``, ``enumerate=False``, ``symmetry=False``...).

    Examples
    --------
    >>> s = builtin_scene("plug2d", rows=3, mu=[0.3, 0.65], mu_c="global")
    >>> s.dim, s.model, s.mu, s.mu_c
    (2, {'rows': 3}, (0.3, 0.65), 'global')
    >>> builtin_scene("plug2d", row=3)
    Traceback (most recent call last):
    hpcwedge.scene.values.SceneError: model.row: unknown parameter of plug2d; did you mean `rows`? (allowed: rows, cols, taper_deg)
    """
    return Scene.builtin(kind, mu=mu, name=name, **params)



def stiffness_scene(K: Any, *, dim: int, null_space: Any = None, mu: float | Sequence[float] = DEFAULT_MU,
                    name: str = "stiffness", **options: Any) -> Scene:
    """The scene of a condensed stiffness given as an array (``kind = "stiffness"``).

    Parameters
    ----------
    K : array_like or scipy sparse matrix, (dim*m, dim*m)
        The condensed, block-ordered local stiffness of the m contact nodes (SPEC §1, §3);
        kept dense (it is dense once condensed).
    dim : int
        2 or 3.
    null_space : array_like, optional
        Its rigid modes as columns; without it a singular K must have an unambiguous null
        space (the parser's rank test).
    mu, name, **options
        As for `builtin_scene` ([compute] and [run] options only).

    Notes
    -----
    The table is checked here; K itself (symmetric, semidefinite, its null space) when the
    scene is solved, as for a scene file.

    Examples
    --------
    One contact node: mu^c = K_tt / |K_nt| (SPEC §6).

    >>> s = stiffness_scene([[2.0, 1.0], [1.0, 4.0]], dim=2, mu=5.0)
    >>> round(solve(s).mu_c, 12)
    4.0
    >>> solve(stiffness_scene([[1.0, 2.0], [0.0, 1.0]], dim=2))
    Traceback (most recent call last):
    hpcwedge.scene.values.SceneError: model.K: not symmetric (max |K - K^T| = 2)
    """
    return Scene.from_stiffness(K, dim=dim, null_space=null_space, mu=mu, name=name, **options)



def truss_scene(nodes: Any, bars: Any, *, contact_nodes: Any, normals: Any, EA: Any = 1.0,
                supports: Any = None, tangents: Any = None, mu: float | Sequence[float] = DEFAULT_MU,
                name: str = "truss", **options: Any) -> Scene:
    """The scene of a truss given as arrays (``kind = "truss"``); dim is the number of
    coordinates per node.

    Parameters
    ----------
    nodes : array_like, (n, dim)
        Node coordinates.
    bars : array_like of int, (b, 2)
        0-based node pairs.
    contact_nodes : array_like of int, (m,)
        The nodes in contact, in the order of the contact list.
    normals : array_like, (m, dim)
        Their contact normals (into the body); 3D: optional `tangents` (m, dim).
    EA : float or array_like, (b,)
        Axial stiffness, one or per bar.
    supports : array_like of int, (s, 2), optional
        [node, dof] pairs held fixed.
    mu, name, **options
        As for `builtin_scene` ([compute] and [run] options only).

    Examples
    --------
    A bar between two walls at 30 degrees from vertical (vgroove_bar): mu^c = tan 30.

    >>> s = truss_scene([[-1.0, 0.0], [1.0, 0.0]], [[0, 1]], contact_nodes=[0, 1], EA=2.0,
    ...                 normals=[[math.cos(math.pi / 6), math.sin(math.pi / 6)],
    ...                          [-math.cos(math.pi / 6), math.sin(math.pi / 6)]])
    >>> abs(solve(s).mu_c - math.tan(math.pi / 6)) < 1e-12
    True
    """
    return Scene.from_truss(nodes, bars, contact_nodes=contact_nodes, normals=normals, EA=EA,
                            supports=supports, tangents=tangents, mu=mu, name=name, **options)
