"""Config overrides ``key=value`` on the command line of this experiment's scripts."""
import ast


def parse_value(v: str):
    """``"32"`` -> 32, ``"(64,32,32)"`` -> (64, 32, 32), ``"true"`` -> True, other text as is."""
    if v.lower() in ("true", "false"):
        return v.lower() == "true"
    try:
        return ast.literal_eval(v)
    except (ValueError, SyntaxError):
        return v
