"""The scene (SPEC §3): a TOML file, or the same tables as a dict, validated into a frozen
`Scene`, and the plan of stages it asks for.

- parse.py: TOML -> Scene (every error names its key), the defaults, the plan.
"""

__all__ = ["parse"]
