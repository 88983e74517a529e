"""The exporter's configuration: a `Config` tree, one module per section, every error naming its key.

`load_config` reads a YAML file and flag overrides; each section's module (`dds`, `ros1`, `zenoh`, `web`,
`fleet`, `metrics`, `events`, `ingest`, `icinga2`) holds its dataclass and its reader, `parsers` what they
share.
"""

from overseer.config.errors import ConfigError
from overseer.config.loading import Config, config_from_dict, load_config

__all__ = ["Config", "ConfigError", "config_from_dict", "load_config"]
