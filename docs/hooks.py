"""The documentation site's build hook (mkdocs.yml: ``hooks``): the tables that come from drivelab's
own registries, so that the pages cannot drift from the code.

A page asks for a table with an HTML comment on a line of its own, ``<!-- drivelab: WHAT ARGS -->``:

- ``scenario NAME``: the scenario's gymnasium id, actions, default reward, backends, traffic levels;
- ``scenario-options NAME``: its declared options (type, range, default, traffic levels' values);
- ``sensor NAME``: the sensor's options (keyword defaults, ranges, size limits) and its space;
- ``actions``, ``reward-terms``, ``reward-presets``, ``algorithms``: the registries' entries;
- ``cli COMMAND``: the command's arguments and options (``benchmark nocrash`` for a subcommand);
- ``results FILE HEADING``: the section of ``benchmarks/results/FILE`` whose heading starts with
  HEADING, up to the next heading (its tables, verbatim: the site never retypes a figure);
- ``results-rows FILE FIRST_CELL``: the first table of FILE, header and the rows whose first cell is
  FIRST_CELL.

It also adds ``benchmarks/results/`` (as ``results/``) and ``notebooks/`` to the site, from where they
are, so the pages can link them. An unknown table, name or heading stops the build.
"""

from __future__ import annotations

import inspect
import re
from pathlib import Path

from mkdocs.exceptions import PluginError
from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

# The scenario registry: its only import in the docs (the scenarios package is moving; one line then).
from drivelab.scenarios import SCENARIOS, gym_id, options_table

REPO = Path(__file__).resolve().parent.parent
RESULTS = REPO / "benchmarks" / "results"
MARKER = re.compile(r"^<!-- drivelab: (?P<what>[\w-]+)(?P<args>[^>]*?) -->$", re.MULTILINE)
# site folder → the folder above the repository's folder of the same name
MOUNTED = {"results": REPO / "benchmarks", "notebooks": REPO}
TRAFFIC_LEVELS = ("empty", "regular", "dense")
SCENARIO_DEFAULT = "<the scenario's>"  # train's --action and --reward
MOUNTED_SUFFIXES = {".md", ".png", ".ipynb", ".csv"}


class DocsError(PluginError):
    """A marker the hook cannot fill: the build stops with this message."""


# --- files from outside docs/ -------------------------------------------------------------------
@event_priority(100)  # before mkdocs-jupyter's on_files, which wraps the notebooks
def on_files(files, config):
    for prefix, parent in MOUNTED.items():
        for path in sorted((parent / prefix).rglob("*")):
            if path.is_file() and path.suffix in MOUNTED_SUFFIXES:
                # a File read from its place (src_dir), as mkdocs-jupyter's wrapper needs
                relative = path.relative_to(parent).as_posix()
                files.append(File(relative, str(parent), config["site_dir"], config["use_directory_urls"]))
    return files


# --- tables -------------------------------------------------------------------------------------
def table(header: list[str], rows: list[list[object]]) -> str:
    def cell(value: object) -> str:
        return str(value).replace("|", "\\|").replace("\n", " ")

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(value) for value in row) + " |" for row in rows]
    return "\n".join(lines)


def code(value: object) -> str:
    return f"`{value}`" if value not in ("", None) else "–"


def scenario_facts(name: str) -> str:
    from drivelab.rewards.shapers import PRESETS

    scenario = _scenario(name)
    backends = ["`fast` (compiled, the default)"]
    if scenario.reference_backend:
        backends.append("`highway` (highway-env's reference)")
    reward = scenario.default_reward
    rows = [
        ["description", scenario.description],
        ["gymnasium id", code(gym_id(name))],
        ["action kinds (the first is the default)", ", ".join(code(kind) for kind in scenario.action_kinds)],
        ["default reward", f"{code(reward)}: {PRESETS[reward].description}"],
        ["backends", ", ".join(backends)],
        ["traffic levels", ", ".join(code(level) for level in scenario.traffic) or "–"],
        ["episode time limit", f"{scenario.config['duration']:g} s (the env keyword `duration_s` sets it)"],
    ]
    return table(["", ""], rows)


def scenario_options(name: str) -> str:
    _scenario(name)
    rows = []
    for row in options_table(name):
        levels = " / ".join(_yaml(row["traffic_levels"].get(level, "–")) for level in TRAFFIC_LEVELS)
        rows.append(
            [code(row["name"]), row["type"], row["range"] or "–", code(_yaml(row["default"])),
             levels if row["traffic_levels"] else "–", row["doc"]]  # fmt: skip
        )
    return table(["option", "type", "range", "default", "empty / regular / dense", "what"], rows)


def sensor(name: str) -> str:
    from drivelab.perception import sensors as registry

    if name not in registry.SENSORS:
        raise DocsError(f"unknown sensor {name!r}")
    cls = registry.SENSORS[name]
    parameters = inspect.signature(cls.__init__).parameters.values()
    rows = []
    for parameter in parameters:
        if parameter.kind is not inspect.Parameter.KEYWORD_ONLY:
            continue
        limit = registry.SIZE_LIMITS.get(name, {}).get(parameter.name)
        low_high = registry.VALUE_RANGES.get(name, {}).get(parameter.name)
        allowed = f"<= {limit}" if limit else (f"[{low_high[0]:g}, {low_high[1]:g}]" if low_high else "–")
        kind = type(parameter.default).__name__ if parameter.default is not None else "str | null"
        rows.append([code(parameter.name), kind, code(_yaml(parameter.default)), allowed])
    rows.append([code("stack"), "int", code(1), ">= 1 (frames stacked along the channel axis)"])
    space = registry.make_sensor(name).space
    text = f"{cls.help[:1].upper()}{cls.help[1:]}.\n\nObservation space with the defaults: `{space}`.\n\n"
    return text + table(["option", "type", "default", "allowed"], rows)


def actions() -> str:
    from drivelab.envs.actions import ACTIONS, make_action

    return table(["action", "what"], [[code(name), make_action(name).describe()] for name in ACTIONS])


def reward_terms() -> str:
    from drivelab.rewards.terms import TERMS

    rows = [[code(name), _first_paragraph(function.__doc__)] for name, function in TERMS.items()]
    return table(["term", "value per step (unweighted)"], rows)


def reward_presets() -> str:
    from drivelab.rewards.shapers import PRESETS

    rows = []
    for name, spec in PRESETS.items():
        weights = ", ".join(f"`{term}` {weight:g}" for term, weight in spec.weights.items())
        extra = []
        if spec.normalize:
            extra.append(f"mapped so that {spec.normalize[0]:g} → 0 and {spec.normalize[1]:g} → 1")
        if spec.gate:
            extra.append(f"multiplied by `{spec.gate}`")
        rows.append([code(name), weights + ("; " + "; ".join(extra) if extra else ""), spec.description])
    return table(["preset", "weights", "what"], rows)


def algorithms() -> str:
    from drivelab.agents.registry import ALGORITHMS

    rows = [
        [code(name), spec.family, ", ".join(code(kind) for kind in spec.action_kinds),
         ", ".join(spec.observation_kinds), "yes" if spec.multi_env else "no", spec.description]  # fmt: skip
        for name, spec in ALGORITHMS.items()
    ]
    return table(["`--algo`", "family", "actions", "observations", "several worlds", "what"], rows)


def cli(*path: str) -> str:
    command = _cli_command(path)
    rows = []
    for parameter in command.params:
        descriptor = getattr(parameter, "type_descriptor", None)
        kind = getattr(getattr(descriptor, "annotation", None), "__name__", None) or str(
            getattr(descriptor, "annotation", "")
        ).replace("typing.", "")
        names = ", ".join(f"`{opt}`" for opt in [*parameter.opts, *parameter.secondary_opts])
        if parameter.param_type_name == "argument":
            names = f"`{parameter.name.upper()}` (argument)"
        default = parameter.default
        if default is None and path == ("train",):  # train's options default to the run config's
            default = _run_config_default(parameter.name)
        shown = "required" if parameter.required else ("–" if default in (None, [], ()) else code(default))
        shown = "the scenario's" if default == SCENARIO_DEFAULT else shown
        rows.append([names, kind, shown, getattr(parameter, "help", None) or ""])
    help_text = _first_paragraph(command.help)
    return f"{help_text}\n\n" + table(["argument / option", "type", "default", "what"], rows)


def results(file: str, *words: str) -> str:
    heading = " ".join(words)
    text = _results_file(file)
    lines = text.splitlines()
    for index, line in enumerate(lines):
        if line.startswith("#") and line.lstrip("#").strip().startswith(heading):
            end = next((j for j in range(index + 1, len(lines)) if lines[j].startswith("#")), len(lines))
            body = "\n".join(lines[index + 1 : end]).strip()
            title = line.lstrip("#").strip()
            return f"From [`benchmarks/results/{file}`](../results/{file}) ({title}):\n\n{body}"
    raise DocsError(f"benchmarks/results/{file} has no heading starting {heading!r}")


def results_rows(file: str, *words: str) -> str:
    first_cell = " ".join(words)
    lines = _results_file(file).splitlines()
    start = next((i for i, line in enumerate(lines) if line.startswith("|")), None)
    if start is None:
        raise DocsError(f"benchmarks/results/{file} has no table")
    end = next((i for i in range(start, len(lines)) if not lines[i].startswith("|")), len(lines))
    rows = [line for line in lines[start + 2 : end] if line.split("|")[1].strip() == first_cell]
    if not rows:
        raise DocsError(f"the first table of benchmarks/results/{file} has no row {first_cell!r}")
    source = f"From [`benchmarks/results/{file}`](../results/{file}):"
    return "\n".join([source, "", *lines[start : start + 2], *rows])


TABLES = {
    "scenario": scenario_facts,
    "scenario-options": scenario_options,
    "sensor": sensor,
    "actions": actions,
    "reward-terms": reward_terms,
    "reward-presets": reward_presets,
    "algorithms": algorithms,
    "cli": cli,
    "results": results,
    "results-rows": results_rows,
}


def on_page_markdown(markdown, page, config, files):
    def fill(match: re.Match) -> str:
        what, args = match["what"], match["args"].split()
        if what not in TABLES:
            raise DocsError(f"{page.file.src_uri}: unknown table {what!r} (known: {', '.join(TABLES)})")
        try:
            filled = TABLES[what](*args)
        except (DocsError, TypeError) as exc:
            marker = f"<!-- drivelab: {what} {' '.join(args)} -->"
            raise DocsError(f"{page.file.src_uri}: {marker}: {exc}") from exc
        if page.file.src_uri.count("/") == 0:  # a top-level page: results/ is a sibling, not a cousin
            filled = filled.replace("](../results/", "](results/")
        return filled

    return MARKER.sub(fill, markdown)


# --- helpers ------------------------------------------------------------------------------------
def _scenario(name: str):
    if name not in SCENARIOS:
        raise DocsError(f"unknown scenario {name!r}")
    return SCENARIOS[name]


def _cli_command(path: tuple[str, ...]):
    import typer.main

    from drivelab.cli import app

    # typer may carry its own copy of click: its Context, and groups known by their list_commands
    command = typer.main.get_command(app)
    context = typer.Context(command)
    for name in path:
        found = command.get_command(context, name) if hasattr(command, "list_commands") else None
        if found is None:
            raise DocsError(f"drivelab has no command {' '.join(path)!r}")
        command, context = found, typer.Context(found, parent=context)
    return command


def cli_commands() -> list[str]:
    """Every command of ``drivelab`` (a group's subcommands as ``group sub``), for the tests."""
    import typer

    group = _cli_command(())
    names = []
    for name in group.list_commands(typer.Context(group)):
        command = _cli_command((name,))
        if hasattr(command, "list_commands"):
            names += [f"{name} {sub}" for sub in command.list_commands(typer.Context(command))]
        else:
            names.append(name)
    return names


def _run_config_default(name: str) -> str | None:
    """A run field's default as `drivelab train` resolves it (None: the option has no field)."""
    import dataclasses

    from drivelab.config import RunConfig

    if name in ("action", "reward"):
        return SCENARIO_DEFAULT
    fields = {field.name: field.default for field in dataclasses.fields(RunConfig)}
    value = fields.get(name, dataclasses.MISSING)
    if value is dataclasses.MISSING or value is None:
        return None
    return ",".join(value) if isinstance(value, tuple) else value


def _results_file(file: str) -> str:
    path = RESULTS / file
    if not path.is_file() or path.parent.resolve() != RESULTS.resolve():
        raise DocsError(f"no results file benchmarks/results/{file}")
    return path.read_text()


def _first_paragraph(text: str | None) -> str:
    return " ".join(inspect.cleandoc(text or "").split("\n\n")[0].split())


def _yaml(value: object) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return str(value).lower()
    return str(value)
