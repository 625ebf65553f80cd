"""Scene files: TOML in SI units read into a validated `Scene`, every bad value named with its key and range."""
from .parse import default_scene_path, load_scene, parse_scene, scene_from_dict
from .toml_out import dumps, scene_toml

__all__ = ["default_scene_path", "dumps", "load_scene", "parse_scene", "scene_from_dict", "scene_toml"]
