"""The scene (SPEC §3): a TOML file, or the same tables as a dict, validated into a frozen
`Scene`, and the plan of stages it asks for.

- values.py: SceneError, the defaults of [compute] and [run], the checks of plain values.
- tables.py: a scene table (and its TOML text) from Python values.
- parse.py: TOML -> Scene (every error names its key), the plan; Scene.builtin & co.
- constructors.py: the documented functions of the API (scene_from_dict, builtin_scene, ...).
"""

__all__ = ["values", "tables", "parse", "constructors"]
