"""YAML read as drivelab reads it everywhere: run configs, sweeps, ``-H`` values, sensor options.

The bottom layer: it imports nothing of drivelab but its errors, so perception's sensor specs and
the run config share one loader.
"""

from __future__ import annotations

import re
from pathlib import Path

import yaml

from drivelab.errors import UsageError


class YamlLoader(yaml.SafeLoader):
    """PyYAML's safe loader, reading ``1e-3`` as the number it is (YAML 1.2) instead of a string,
    and refusing a mapping that repeats a key (YAML forbids it; PyYAML would keep the last value)."""

    def compose_mapping_node(self, anchor):
        # checked as composed, before the constructor flattens merge keys (``<<: *base``) into the
        # mappings that use them, in place: a merged key given again overrides it, as YAML means
        node = super().compose_mapping_node(anchor)
        seen = set()
        for key_node, _ in node.value:
            if not isinstance(key_node, yaml.ScalarNode) or key_node.tag == "tag:yaml.org,2002:merge":
                continue
            if (key_node.tag, key_node.value) in seen:
                raise yaml.composer.ComposerError(
                    "while composing a mapping", node.start_mark, f"duplicate key {key_node.value!r}",
                    key_node.start_mark,
                )  # fmt: skip
            seen.add((key_node.tag, key_node.value))
        return node


class YamlDumper(yaml.SafeDumper):
    """PyYAML's safe dumper, quoting the strings that ``YamlLoader`` would read as numbers (``"1e5"``),
    so that what it writes reads back as it was, with either loader."""


for _resolving in (YamlLoader, YamlDumper):
    _resolving.add_implicit_resolver(
        "tag:yaml.org,2002:float",
        re.compile(r"^[-+]?(?:\d+\.?\d*|\.\d+)[eE][-+]?\d+$"),
        list("-+0123456789."),
    )


def parse_yaml(text: str):
    """``text`` as YAML, with ``YamlLoader``."""
    return yaml.load(text, Loader=YamlLoader)


def dump_yaml(data) -> str:
    """``data`` (plain containers, strings, numbers) as YAML that ``parse_yaml`` reads back equal."""
    return yaml.dump(data, Dumper=YamlDumper, sort_keys=False)


def load_yaml(path: str | Path) -> dict:
    """Read a YAML mapping, with a one-line error for a missing or malformed file."""
    path = Path(path)
    if path.is_dir():
        raise UsageError(f"config file {str(path)!r} is a folder, not a YAML file")
    if not path.is_file():
        raise UsageError(f"config file {str(path)!r} does not exist")
    try:
        data = parse_yaml(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError as exc:
        raise UsageError(f"config file {str(path)!r} is not UTF-8 text (byte {exc.start})") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise UsageError(f"malformed YAML in {str(path)!r}{where}: {getattr(exc, 'problem', exc)}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise UsageError(f"{str(path)!r} must hold a mapping of config fields, not {type(data).__name__}")
    return data
