"""Model families (truss, continuum meshes, matrices assembled elsewhere) and the built-in scenes of SPEC §6."""
from hpcwedge.models.continuum import continuum_stiffness, q4_stiffness
from hpcwedge.models.library import BUILTIN_DIM, BUILTINS, block2d, builtin, plug2d, plug3d, vgroove_bar
from hpcwedge.models.rigid import rigid_modes
from hpcwedge.models.truss import truss_model, truss_stiffness

__all__ = ["BUILTINS", "BUILTIN_DIM", "block2d", "builtin", "plug2d", "plug3d", "vgroove_bar",
           "continuum_stiffness", "q4_stiffness", "rigid_modes", "truss_model", "truss_stiffness"]
