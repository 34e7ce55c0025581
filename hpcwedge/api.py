"""The public Python API (``import hpcwedge as hw``): scenes, solving, result files, figures.

A thin layer over the stages the command line runs: every scene, however it is made, is a
scene table that goes through the one validator (scene.parse_scene), so every check,
default and error message (a SceneError naming the key) is the parser's; `solve` is
run.pipeline.run_scene and `contact_problem` its condensation; the result file, its JSON,
the figure and the VTU export are results/hdf5.py, post/plot.py, post/recovery.py and
post/export.py.

A scene made in Python (a dict, keyword arguments, arrays) keeps its table as TOML text
(Scene.text): its hash identifies it, and a result file stores it, so that `show`, `plot`
and `export` rebuild the body from the file alone, as for a scene file.

Examples
--------
>>> import math
>>> import hpcwedge as hw
>>> r = hw.solve(hw.Scene.builtin("plug2d", rows=4))
>>> abs(r.mu_c - math.tan(math.radians(10))) < 1e-12
True
>>> [(run.mu, run.n_wedged_rays, run.n_cones) for run in r.runs]
[(0.65, 244, 3)]
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator, Mapping
from typing import Any

from hpcwedge.contact.problem import ContactProblem
from hpcwedge.files import FileError
from hpcwedge.results.record import NOT_COMPUTED, Cone, Pattern, Result, Run
from hpcwedge.run.pipeline import run_scene
from hpcwedge.scene.constructors import DEFAULT_MU, builtin_scene, scene_from_dict, stiffness_scene, truss_scene
from hpcwedge.scene.parse import Scene, load_scene
from hpcwedge.scene.values import SceneError

__all__ = ["Scene", "SceneError", "FileError", "Result", "Run", "Cone", "Pattern", "NOT_COMPUTED", "ContactProblem",
           "solve", "contact_problem", "read_result", "write_result", "plot", "export_vtu", "DEFAULT_MU",
           "scene_from_dict", "builtin_scene", "stiffness_scene", "truss_scene"]

# --------------------------------------------------------------------------- solving, files

def solve(scene: Scene | str | os.PathLike | Mapping, *, progress: bool = False) -> Result:
    """Every answer the scene asks for (pipeline.run_scene, in this process).

    Parameters
    ----------
    scene : Scene, path or dict
        A Scene, a scene file (Scene.load) or a scene table (Scene.from_dict).
    progress : bool
        Show progress on stderr.

    Returns
    -------
    Result
        ``mu_c`` (None: none found), ``mu_c_status``, ``runs`` (one Run per listed mu:
        ``rays``, ``trivial_rays`` (numpy arrays), ``cones`` (Cone records), ``patterns``
        (Pattern records) and their counts ``n_*``; None for what the scene did not ask
        for), ``stats``, ``timings``, ``to_dict()`` (the ``show --json`` object).

    Examples
    --------
    >>> r = solve(Scene.builtin("plug2d", rows=3))
    >>> r.m, r.runs[0].n_wedged_rays, r.runs[0].rays.shape, sorted(r.timings)
    (6, 44, (44, 24), ['condense', 'enumerate', 'mu_c', 'total'])
    """
    from hpcwedge.progress import Progress
    return run_scene(_scene(scene), Progress(quiet=not progress))


def contact_problem(scene: Scene | str | os.PathLike | Mapping) -> ContactProblem:
    """The condensed problem of a scene, what `solve` works on (its condense stage).

    Parameters
    ----------
    scene : Scene, path or dict
        As for `solve`.

    Returns
    -------
    ContactProblem
        ``K`` (dim*m x dim*m): the body's stiffness condensed to the contact DOFs, local
        frames, block ordering (SPEC §1), scaled by a power of two that changes no answer
        (contact.build.stiffness_exponent); ``N``: its rigid modes (no columns for a
        supported body); ``dim``, ``m``.

    Examples
    --------
    >>> p = contact_problem(Scene.builtin("plug2d", rows=3))
    >>> p.m, p.K.shape, p.N.shape
    (6, (12, 12), (12, 3))
    """
    from hpcwedge.contact.build import contact_problem as condensed
    return condensed(_scene(scene))


def _scene(scene: Scene | str | os.PathLike | Mapping) -> Scene:
    """A Scene, a scene file (load_scene) or a scene table (scene_from_dict) as a Scene."""
    if isinstance(scene, (str, os.PathLike)):
        return load_scene(os.fspath(scene))
    if isinstance(scene, Mapping):
        return scene_from_dict(scene)
    if not isinstance(scene, Scene):
        raise SceneError(f"scene: a Scene, a scene file or a dict, got {type(scene).__name__}")
    return scene


def write_result(result: Result, path: str | os.PathLike) -> None:
    """Write `result` as a result file (SPEC §4; atomic, checksummed: results.hdf5.write_result),
    which ``hpcwedge show``, ``plot`` and ``export`` read like one written by ``hpcwedge run``.
    FileError (one line, nothing written) where ``run -o`` would refuse the path: an existing
    file that is neither empty nor HDF5, a directory, a missing or read-only folder."""
    from hpcwedge.files import check_output
    from hpcwedge.results.hdf5 import write_result as write
    if not isinstance(result, Result):
        raise TypeError(f"write_result: result must be a Result (hpcwedge.solve), got {type(result).__name__}")
    # as `hpcwedge run -o`: an existing file is replaced only if it is empty or HDF5, the
    # folder must exist (FileError, one line)
    check_output(os.fspath(path), replaces_hdf5_only=True)
    write(os.fspath(path), result)


def read_result(path: str | os.PathLike, *, with_rays: bool = True) -> Result:
    """The Result a result file holds, as `write_result` took it (results.hdf5.read_result):
    the same scene, runs (rays bit for bit), mu^c, stats and timings; ``model`` is the body
    the file keeps for figures (coordinates, contact nodes, normals, cells) and ``problem``
    is None (`contact_problem` of ``result.scene`` rebuilds it). with_rays False: the ray
    arrays are not read (None; their counts ``n_*`` kept). ``to_dict()`` is the file's
    ``hpcwedge show --json`` object. FileError (one line) for a missing, damaged or
    malformed file.

    Examples
    --------
    >>> import os, tempfile
    >>> r = solve(Scene.builtin("vgroove_bar", mu=1.0))
    >>> with tempfile.TemporaryDirectory() as d:
    ...     write_result(r, os.path.join(d, "r.h5"))
    ...     back = read_result(os.path.join(d, "r.h5"))
    >>> back.scene == r.scene, back.mu_c == r.mu_c, back.runs[0].cones == r.runs[0].cones
    (True, True, True)
    >>> back.to_dict() == r.to_dict()
    True
    """
    from hpcwedge.results.hdf5 import read_result as read
    return read(os.fspath(path), with_rays=with_rays)


def _indices(**given: Any) -> dict:
    """The given indices (None: left out), each a whole number (ValueError naming it: 1.9 or
    "1" are not silently truncated to 1)."""
    import numbers
    out = {}
    for name, v in given.items():
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, numbers.Integral):
            raise ValueError(f"{name}: a whole number, got {v!r}")
        out[name] = int(v)
    return out


def _inputs(result: Result | str | os.PathLike) -> tuple[str, ...]:
    """The result file an output must not replace (none for a Result in memory)."""
    return () if isinstance(result, Result) else (os.fspath(result),)


@contextlib.contextmanager
def _result_file(result: Result | str | os.PathLike) -> Iterator[str]:
    """The path of a result file: `result` itself, or a Result written to a temporary file."""
    if not isinstance(result, Result):
        yield os.fspath(result)
        return
    with tempfile.TemporaryDirectory(prefix="hpcwedge-") as d:
        path = os.path.join(d, "result.h5")
        write_result(result, path)
        yield path


def plot(result: Result | str | os.PathLike, output: str | os.PathLike, *, run: int = -1,
         ray: int | None = None, pattern: int | None = None) -> None:
    """Draw a wedged configuration and the cones' mu^c as a PNG, PDF or SVG (``hpcwedge
    plot``: plot.plot_result).

    Parameters
    ----------
    result : Result or path
        A solved Result or a result file.
    output : path
        The figure to write (atomically), in the format of its suffix: .png (or none),
        .pdf, .svg.
    run : int
        Which run (Python-style index, -1: the last).
    ray, pattern : int, optional
        2D: the wedged ray to draw (default 0); 3D: the sign pattern (plot.plot_result's
        choices and defaults; only the one given is passed on).

    Raises
    ------
    ValueError
        One line: a bad index, a missing or damaged file, an output that cannot be
        written or would replace another kind of file (FileError).
    """
    from hpcwedge.files import check_output
    from hpcwedge.post.plot import figure_format, plot_result
    item = _indices(run=run, ray=ray, pattern=pattern)
    check_output(os.fspath(output), _inputs(result), figure_format)
    with _result_file(result) as path:
        plot_result(path, os.fspath(output), **item)


def export_vtu(result: Result | str | os.PathLike, output: str | os.PathLike, *, run: int = -1,
               ray: int | None = None, cone: int | None = None, pattern: int | None = None):
    """Write one configuration of the whole body as a VTU file (``hpcwedge export``) and
    return it.

    Parameters
    ----------
    result : Result or path
        A solved Result or a result file.
    output : path
        The .vtu file to write (ParaView; another suffix: ValueError).
    run : int
        Which run (Python-style index, -1: the last).
    ray, cone, pattern : int
        Exactly one: a wedged ray (2D), a cone (2D: the mean of its wedged rays) or a sign
        pattern (a feasible point at the run's mu).

    Returns
    -------
    recovery.Configuration
        ``displacement`` and ``reaction`` of every node, ``element_values`` (von Mises,
        bar forces) of every element, ``model``, ``label``.

    Raises
    ------
    recovery.ConfigurationError
        One line: a bad index, a result without a body (a stiffness scene), a bad file.
    ValueError
        An output name that does not end in .vtu.

    Examples
    --------
    >>> import os, tempfile
    >>> r = solve(Scene.builtin("plug2d", rows=2))
    >>> with tempfile.TemporaryDirectory() as d:
    ...     c = export_vtu(r, os.path.join(d, "ray0.vtu"), ray=0)
    ...     os.path.getsize(os.path.join(d, "ray0.vtu")) > 0
    True
    >>> c.displacement.shape
    (6, 2)
    """
    from hpcwedge.files import check_output
    from hpcwedge.post.export import check_vtu_name, write_vtu
    from hpcwedge.post.recovery import load_configuration
    item = _indices(run=run, ray=ray, cone=cone, pattern=pattern)
    check_output(os.fspath(output), _inputs(result), check_vtu_name)
    with _result_file(result) as path:
        config = load_configuration(path, **item)
    write_vtu(config, os.fspath(output))
    return config
