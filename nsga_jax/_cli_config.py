"""``nsga-jax scenes`` and ``nsga-jax config``: what there is to run, and
configs to save and edit."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

from ._results import ConfigError


def scenes_command(args: argparse.Namespace | None = None) -> int:
    """Print the built-in scenes, their parameters (default, unit, meaning,
    range) and observables."""
    from ._scenes import REGISTRY

    for name, spec in sorted(REGISTRY.items()):
        print(f"{name}: {spec.description}")
        for key, p in spec.parameters.items():
            unit = f" [{p.unit}]" if p.unit else ""
            print(f"    {key} = {p.default!r}{unit}  {p.doc}; {p.range_text()}")
        print(f"    observables: {', '.join(spec.observables)}")
    return 0


def config_command(args: argparse.Namespace) -> int:
    """``config --list``: the packaged configs, system files and scene files;
    ``config SCENE``: the default config of a built-in scene, a system file or
    a ``.py`` scene file (naming a file by its absolute path); ``config
    CONFIG.toml``: that config as it is, its scene file named by its absolute
    path. Either way the text runs from any folder once saved."""
    if args.list:
        if args.scene is not None:
            raise ConfigError(f"config --list takes no scene, got {args.scene!r}")
        return _list()
    if args.scene is None:
        raise ConfigError("config expects a scene name, a system file, a .py scene file or a .toml config "
                          "(or --list for the packaged ones)")
    from ._scenes import REGISTRY, resolve_scene

    name, path = resolve_scene(args.scene)
    if path is not None:
        print(_config_text(path), end="")
        return 0
    text = REGISTRY[name].default_toml()
    if name != str(args.scene):  # a scene file: the config names it by its absolute path, read from anywhere
        from ._packaged import locate

        file, colon, chosen = str(args.scene).partition(".py:")
        absolute = str(locate(file + ".py" if colon else file).resolve()) + (f":{chosen}" if colon else "")
        text = text.replace(f'scene = "{name}"', f"scene = {json.dumps(absolute)}", 1)
    print(text, end="")
    return 0


def _config_text(path: Path) -> str:
    """A config file's text, a relative scene file in it (read relative to the
    config's folder) named by its absolute path instead."""
    from ._packaged import SUFFIXES
    from ._scenes import read_toml

    text = path.read_text()
    file, colon, chosen = str(read_toml(path).get("scene", "")).partition(".py:")
    file = file + ".py" if colon else file
    if file.endswith(SUFFIXES) and not Path(file).expanduser().is_absolute():
        absolute = str((path.parent / file).resolve()) + (f":{chosen}" if colon else "")
        text = re.sub(r"^scene\s*=.*$", lambda _: f"scene = {json.dumps(absolute)}", text, count=1, flags=re.M)
    return text


def _list() -> int:
    from ._packaged import ROOT, first_comment, packaged_files

    names = packaged_files()
    width = max(len(n) for n in names)
    print(f"packaged configs and scene files, read by these names from any folder (installed in {ROOT}):")
    for name in names:
        print(f"  {name:<{width}}  {first_comment(ROOT / name)}")
    print("`nsga-jax config NAME > my.toml` saves a config (or a scene's default config) to edit; "
          "`nsga-jax run my.toml` runs it")
    return 0


__all__ = ["config_command", "scenes_command"]
