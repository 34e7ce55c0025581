"""The scene (SPEC §3): a TOML file, or the same tables as a dict, validated into a frozen
`Scene`, and the plan of stages it asks for.

- keys.py: the one table of scene keys (type, values, default, unit, meaning, run setting or not).
- values.py: SceneError, the defaults of [compute] and [run], the checks of plain values.
- tables.py: a scene table (and its TOML text) from Python values.
- parse.py: TOML -> Scene (every error names its key), the plan, the record that checkpoints
  and results compare (scene_record, changed_settings); Scene.builtin & co.
- constructors.py: the documented functions of the API (scene_from_dict, builtin_scene, ...).
"""

__all__ = ["keys", "values", "tables", "parse", "constructors"]
