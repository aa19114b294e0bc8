"""Configuration: schema (validated models), YAML loading, --set overrides, variants."""

from .load import load_config, parse_overrides, resolved_yaml
from .schema import Config

__all__ = ["Config", "load_config", "parse_overrides", "resolved_yaml"]
