"""YAML read as drivelab reads it everywhere: run configs, sweeps, ``-H`` values, sensor options. It
imports nothing of drivelab but its errors."""

from __future__ import annotations

import re
from pathlib import Path

import yaml

from drivelab.errors import UsageError

# What a file drivelab reads may hold: far more than its own files need, far less than a "billion
# laughs" of aliases or brackets nested deeper than Python recurses.
MAX_YAML_BYTES = 1 << 20
MAX_YAML_DEPTH = 64
MAX_YAML_VALUES = 100_000  # scalars, lists and mappings, every alias counted as what it repeats


class BoundedLoader(yaml.SafeLoader):
    """PyYAML's safe loader (YAML 1.1, as RL Zoo reads its files) that refuses, while composing, a
    document nested deeper than ``MAX_YAML_DEPTH``, one holding more than ``MAX_YAML_VALUES``
    values once its aliases are expanded, and an alias inside the node it names (a recursive
    structure): ``yaml.composer.ComposerError``, a ``yaml.YAMLError``."""

    def __init__(self, stream) -> None:
        super().__init__(stream)
        self._depth = 0
        self._sizes: dict[int, int] = {}  # id of each finished node → its values, aliases expanded

    def compose_document(self):
        try:
            return super().compose_document()
        finally:
            self._sizes = {}

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            node = super().compose_node(parent, index)
            if id(node) not in self._sizes:  # still being composed: the alias is inside its anchor
                raise yaml.composer.ComposerError(
                    None, None, f"alias *{event.anchor} is inside the node it names (a recursive structure)",
                    event.start_mark,
                )  # fmt: skip
            return node
        self._depth += 1
        try:
            if self._depth > MAX_YAML_DEPTH:
                raise yaml.composer.ComposerError(
                    None, None, f"nested more than {MAX_YAML_DEPTH} levels deep", self.peek_event().start_mark
                )
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
        size = 1
        if isinstance(node, yaml.SequenceNode):
            size += sum(self._sizes[id(item)] for item in node.value)
        elif isinstance(node, yaml.MappingNode):
            size += sum(self._sizes[id(key)] + self._sizes[id(value)] for key, value in node.value)
        if size > MAX_YAML_VALUES:
            raise yaml.composer.ComposerError(
                None, None, f"holds more than {MAX_YAML_VALUES} values once its aliases are expanded",
                node.start_mark,
            )  # fmt: skip
        self._sizes[id(node)] = size
        return node


class YamlLoader(BoundedLoader):
    """``BoundedLoader`` reading ``1e-3`` as the number it is (YAML 1.2) instead of a string,
    refusing a mapping that repeats a key (YAML forbids it; PyYAML would keep the last value) and
    one whose key is not a string (every field drivelab reads is named by one)."""

    def compose_mapping_node(self, anchor):
        # checked as composed, before the constructor flattens merge keys (``<<: *base``) into the
        # mappings that use them, in place: a merged key given again overrides it, as YAML means
        node = super().compose_mapping_node(anchor)
        seen = set()
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            if not isinstance(key_node, yaml.ScalarNode) or key_node.tag != "tag:yaml.org,2002:str":
                problem = "a key is not a string"
                if isinstance(key_node, yaml.ScalarNode):
                    problem = f"key {key_node.value!r} is not a string (quote it)"
                raise yaml.composer.ComposerError(
                    "while composing a mapping", node.start_mark, problem, key_node.start_mark
                )
            if key_node.value in seen:
                raise yaml.composer.ComposerError(
                    "while composing a mapping", node.start_mark, f"duplicate key {key_node.value!r}",
                    key_node.start_mark,
                )  # fmt: skip
            seen.add(key_node.value)
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


def parse_yaml_1_1(text: str):
    """``text`` as ``yaml.safe_load`` reads it (YAML 1.1: RL Zoo's hyper-parameter files), within
    ``BoundedLoader``'s bounds."""
    return yaml.load(text, Loader=BoundedLoader)


def dump_yaml(data) -> str:
    """``data`` (plain containers, strings, numbers) as YAML that ``parse_yaml`` reads back equal."""
    return yaml.dump(data, Dumper=YamlDumper, sort_keys=False)


def read_text_bounded(path: Path, what: str = "config file") -> str:
    """The UTF-8 text of ``path``, refused (a one-line UsageError) when it is larger than
    ``MAX_YAML_BYTES``: read up to that, never the whole of a huge file or a device."""
    with path.open("rb") as handle:
        data = handle.read(MAX_YAML_BYTES + 1)
    if len(data) > MAX_YAML_BYTES:
        raise UsageError(
            f"{what} {str(path)!r} is larger than {MAX_YAML_BYTES >> 20} MiB: not a drivelab YAML file"
        )
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UsageError(f"{what} {str(path)!r} is not UTF-8 text (byte {exc.start})") from None


def load_yaml(path: str | Path) -> dict:
    """Read a YAML mapping, with a one-line error for a missing, oversized or malformed file."""
    path = Path(path)
    if path.is_dir():
        raise UsageError(f"config file {str(path)!r} is a folder, not a YAML file")
    if not path.is_file():
        raise UsageError(f"config file {str(path)!r} does not exist")
    try:
        data = parse_yaml(read_text_bounded(path))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise UsageError(f"malformed YAML in {str(path)!r}{where}: {getattr(exc, 'problem', exc)}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise UsageError(f"{str(path)!r} must hold a mapping of config fields, not {type(data).__name__}")
    return data
