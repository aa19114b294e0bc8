"""Loading a config: YAML file -> variant -> --set overrides -> schema validation -> cross checks.

Every failure raises InputError with one line that names the file or the key.
"""

from __future__ import annotations

import copy
import re
from pathlib import Path

import yaml
from pydantic import ValidationError


class _Loader(yaml.SafeLoader):
    """YAML 1.1 safe loader that also reads 1e-6 and 1E+3 as numbers (YAML 1.1 wants a dot: 1.0e-6)."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
    |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
    |\.[0-9_]+(?:[eE][-+][0-9]+)?
    |[-+]?\.(?:inf|Inf|INF)
    |\.(?:nan|NaN|NAN))$""", re.X),
    list("-+0123456789."))

from ..errors import InputError
from .base import RULE_ERROR
from .schema import CONFIG, MODE_SECTIONS, Config


def parse_overrides(items) -> list[tuple[str, object]]:
    """Parse `key.sub=value` strings; values are YAML scalars or flow lists (`[0, 1]`)."""
    out = []
    for item in items or []:
        if "=" not in item:
            raise InputError(f"--set '{item}': expected key=value")
        key, raw = item.split("=", 1)
        key = key.strip()
        if not key:
            raise InputError(f"--set '{item}': empty key")
        try:
            value = yaml.load(raw, Loader=_Loader) if raw.strip() != "" else ""
        except yaml.YAMLError:
            raise InputError(f"--set '{item}': value is not valid YAML") from None
        out.append((key, value))
    return out


def set_dotted(data: dict, key: str, value) -> None:
    """Set data[a][b][c] = value for key 'a.b.c'; integer parts index lists ('a.0.b' or 'a[0].b')."""
    parts = re.sub(r"\[(\d+)\]", r".\1", key).split(".")
    node = data
    for n, part in enumerate(parts[:-1]):
        nxt = parts[n + 1]
        if isinstance(node, list):
            idx = _index(node, part, key)
            node = node[idx]
            continue
        if part not in node or node[part] is None:
            node[part] = [] if nxt.isdigit() else {}
        node = node[part]
        if not isinstance(node, (dict, list)):
            raise InputError(f"config key '{'.'.join(parts[:n + 1])}' is a value, not a section (in --set {key})")
    last = parts[-1]
    if isinstance(node, list):
        node[_index(node, last, key)] = value
    else:
        node[last] = value


def _index(node: list, part: str, key: str) -> int:
    if not part.isdigit():
        raise InputError(f"config key '{key}': '{part}' must be a list index")
    idx = int(part)
    if idx >= len(node):
        raise InputError(f"config key '{key}': index {idx} out of range (list has {len(node)} entries)")
    return idx


def read_yaml(path) -> dict:
    p = Path(path)
    if p.is_dir():
        raise InputError(f"config file '{path}' is a directory")
    if not p.is_file():
        raise InputError(f"config file '{path}' does not exist")
    try:
        data = yaml.load(p.read_text(), Loader=_Loader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark is not None else ""
        raise InputError(f"config file '{path}'{where}: not valid YAML") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"config file '{path}': cannot be read ({exc.__class__.__name__})") from None
    if not isinstance(data, dict):
        raise InputError(f"config file '{path}': expected a mapping of keys at the top level")
    return data


def apply_variant(raw: dict, variant: str, what: str = "--variant") -> None:
    """Apply the config's named variant (its dotted overrides) to the raw mapping in place and mark the
    description; InputError naming `what` (the option or key that asked for it) when it is not defined."""
    variants = raw.get("variants") or {}
    if not isinstance(variants, dict) or variant not in variants:
        names = ", ".join(sorted(variants)) if isinstance(variants, dict) and variants else "none"
        raise InputError(f"{what} '{variant}': not defined in the config (variants: {names})")
    for key, value in (variants[variant] or {}).items():
        set_dotted(raw, key, copy.deepcopy(value))
    raw.setdefault("description", "")
    raw["description"] = (str(raw["description"]) + f" [variant {variant}]").strip()


def load_config(path=None, overrides=(), variant: str | None = None, data: dict | None = None) -> Config:
    """Build a validated Config from a YAML file (or a dict), a variant name and `key=value` overrides."""
    raw = copy.deepcopy(data) if data is not None else read_yaml(path)
    if variant:
        apply_variant(raw, variant)
    for key, value in parse_overrides(overrides):
        set_dotted(raw, key, value)
    try:
        cfg = CONFIG.validate_python(raw)
    except ValidationError as exc:
        raise InputError(format_validation_error(exc, path)) from None
    return cfg


def format_validation_error(exc: ValidationError, path=None) -> str:
    """One line: the first problem, naming its key, with a count of the others. Problems of a key's own
    type or range come before the cross-field rules (which are reported alone, without the file: the
    first rule that fails, as "config key '<key>': <message>")."""
    errors = [_untagged(e) for e in exc.errors()]
    if errors[0].get("type") == "union_tag_invalid":
        tags = errors[0].get("ctx", {}).get("expected_tags", "")
        return f"config key 'mode'{f' in {path!r}' if path else ''}: must be one of {tags} " \
               f"(got {errors[0].get('ctx', {}).get('tag')!r})"
    plain = [e for e in errors if e.get("type") != RULE_ERROR]
    if not plain:
        rule = errors[0]
        ctx = rule.get("ctx", {})
        key = ".".join(k for k in (_loc(rule.get("loc", ())) if rule.get("loc") else "", ctx.get("key", "")) if k)
        return f"config key '{key}': {ctx.get('message', rule.get('msg', 'invalid'))}"
    errors = plain
    first = errors[0]
    key = _loc(first.get("loc", ()))
    kind = first.get("type", "")
    other = _other_mode_section(first)
    if other is not None:
        key = _first_leaf(key, first.get("input"))
        msg = f"applies to mode {other} only (mode is {first['mode']})"
    elif kind == "extra_forbidden":
        msg = "unknown key"
    elif kind == "missing":
        msg = "required key is missing"
    else:
        msg = first.get("msg", "invalid").replace("Value error, ", "")
        if "input" in first and kind not in ("model_type",):
            got = first["input"]
            text = repr(got)
            if len(text) <= 60:
                msg += f" (got {text})"
    more = f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})" if len(errors) > 1 else ""
    src = f" in '{path}'" if path else ""
    return f"config key '{key}'{src}: {msg}{more}"


def _untagged(error: dict) -> dict:
    """A validation error of a case with the union's tag (the mode, first in its location) moved from the
    location to `error["mode"]`."""
    loc = tuple(error.get("loc", ()))
    if loc and loc[0] in MODE_SECTIONS:
        return {**error, "loc": loc[1:], "mode": loc[0]}
    return error


def _other_mode_section(error: dict) -> str | None:
    """The mode whose own section a case of the other mode set (an unknown top-level key that the other
    mode accepts), or None."""
    loc = error.get("loc", ())
    if error.get("type") != "extra_forbidden" or len(loc) != 1 or "mode" not in error:
        return None
    return next((m for m, keys in MODE_SECTIONS.items() if m != error["mode"] and loc[0] in keys), None)


def _first_leaf(key: str, value) -> str:
    """The dotted name of the first key set inside a section given as `value` (the section itself when it
    holds no keys), or of a list's first item: `wcsph.air.cohesion` for `wcsph: {air: {cohesion: 10}}`,
    `inflow[0]` for a list of inflows."""
    while isinstance(value, dict) and value:
        name, value = next(iter(value.items()))
        key = f"{key}.{name}"
    if isinstance(value, list) and value:
        key = f"{key}[0]"
    return key


def _loc(loc) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part in ("float", "constrained-float", "literal['auto']") or part.startswith("function-"):
            continue
        else:
            out += ("." if out else "") + str(part)
    return out or "(top level)"


def resolved_yaml(cfg: Config) -> str:
    """The fully resolved config (defaults filled in) as YAML text."""
    data = cfg.model_dump(mode="json")
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=None)




def load_run_config(run_path, overrides=()) -> Config:
    """The validated Config stored in a run file (attribute config_yaml), with `key=value` overrides."""
    from ..io.hdf5 import RunFile, RunFileError

    try:
        with RunFile(run_path) as rf:
            raw = yaml.safe_load(rf.config_yaml)
    except RunFileError as exc:
        raise InputError(str(exc)) from None
    except yaml.YAMLError:
        raw = None
    if not isinstance(raw, dict):
        raise InputError(f"{run_path}: the run file holds no readable config")
    # a run file written before the case models were split by mode holds the other mode's sections at
    # their defaults, which a case of this mode does not accept
    mode = raw.get("mode", "isph")
    for other, keys in MODE_SECTIONS.items():
        if other != mode:
            for key in keys:
                raw.pop(key, None)
    return load_config(data=raw, overrides=overrides)
