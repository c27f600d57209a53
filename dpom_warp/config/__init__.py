"""Run configuration: YAML validated once, at the edge, into typed objects.

The config's form is a tree of pydantic models (`ConfigFile` and its sections): one source
for validation, defaults, the JSON Schema that editors use (`dpom-warp schema`) and the
README's config reference (`python -m bench.docs`). Every error is one line naming the key,
what was expected and what was found. Relative paths in a config file are relative to the
file's folder; those given with `--set` (or in a mapping) to the current folder.

The package, by section: `values` (the value types and `Node`, a mapping that names unknown
keys), `camera`, `model_section`, `sections` (the others), `schema` (the whole file, its JSON
Schema, errors in one line), `read` (YAML, --set, relative paths, camera files) and `run` (the
typed RunConfig that `parse_config` builds, reading no file). Filling the camera keys in from a
recording is `dpom_warp.loading`'s (it opens the recording; this package opens none).
"""

from .camera import CameraFile, load_camera_file
from .read import apply_overrides, camera_from_file, camera_shorthand, read_config, resolve_paths
from .run import Detection, EngineOptions, Evaluation, Inputs, Output, RunConfig, config_key, parse_config, source_of
from .schema import ConfigFile, json_schema, path_keys
from ..values import ConfigError, Node, check_device

__all__ = ["CameraFile", "ConfigError", "ConfigFile", "Detection", "EngineOptions", "Evaluation", "Inputs", "Node",
           "Output", "RunConfig", "apply_overrides", "camera_from_file", "camera_shorthand", "check_device",
           "config_key", "json_schema", "load_camera_file", "parse_config", "path_keys", "read_config", "resolve_paths",
           "source_of"]
