"""Every scenario, sensor, action kind, reward term and preset, algorithm and command has its entry in
the documentation, written by a person: the names come from drivelab's registries, and a generated
table alone does not count."""

import re

import yaml

from drivelab.agents.registry import ALGORITHMS
from drivelab.envs.actions import ACTIONS
from drivelab.perception.sensors import SENSORS
from drivelab.rewards.shapers import PRESETS
from drivelab.rewards.terms import TERMS
from tests.docs.pages import DOCS, REPO, headings, hooks, prose

HOOKS = hooks()


def _missing(names, present) -> list[str]:
    return [name for name in names if name not in present]


def _nav_pages() -> set[str]:
    def walk(node):
        if isinstance(node, str):
            yield node
        elif isinstance(node, dict):
            for value in node.values():
                yield from walk(value)
        elif isinstance(node, list):
            for item in node:
                yield from walk(item)

    config = yaml.load((REPO / "mkdocs.yml").read_text(), Loader=yaml.BaseLoader)
    return set(walk(config["nav"]))


def test_every_scenario_has_a_page_in_the_nav_with_its_tables():
    nav, listed = _nav_pages(), prose(DOCS / "scenarios" / "index.md")
    for name in HOOKS.SCENARIOS:
        page = DOCS / "scenarios" / f"{name}.md"
        assert page.is_file(), f"scenario {name!r} has no page docs/scenarios/{name}.md"
        assert f"scenarios/{name}.md" in nav, f"docs/scenarios/{name}.md is not in mkdocs.yml's nav"
        assert f"]({name}.md)" in listed, f"docs/scenarios/index.md does not link scenario {name!r}"
        text = page.read_text()
        for table in (f"<!-- drivelab: scenario {name} -->", f"<!-- drivelab: scenario-options {name} -->"):
            assert table in text, f"docs/scenarios/{name}.md lacks {table}"
        assert len(prose(page).split()) >= 60, f"docs/scenarios/{name}.md says too little of {name!r}"


def _sections(page: str, names, table: str | None = None) -> list[str]:
    """The names without a heading `name` in docs/page (and, with ``table``, its generated table)."""
    path = DOCS / page
    present = {heading.strip("`") for heading in headings(path)}
    text = path.read_text()
    if table is not None:
        present = {name for name in present if f"<!-- drivelab: {table} {name} -->" in text}
    return _missing(names, present)


def test_every_sensor_has_a_section_with_its_options():
    assert _sections("sensors.md", SENSORS, table="sensor") == []


def test_every_action_kind_has_a_section():
    assert _sections("actions.md", ACTIONS) == []


def test_every_reward_preset_has_a_section():
    assert _sections("rewards.md", PRESETS) == []


def test_every_reward_term_is_named_in_the_rewards_page():
    written = set(re.findall(r"`(\w+)`", prose(DOCS / "rewards.md")))
    assert _missing(TERMS, written) == []


def test_every_algorithm_is_named_in_the_algorithms_page():
    written = set(re.findall(r"`(\w+)`", "\n".join(headings(DOCS / "algorithms.md"))))
    assert _missing(ALGORITHMS, written) == []


def test_every_command_has_a_section_with_its_options():
    assert _sections("cli.md", HOOKS.cli_commands(), table="cli") == []


def test_the_readme_fits_on_a_screen_or_two_and_its_links_resolve():
    readme = (REPO / "README.md").read_text()
    assert len(readme.splitlines()) <= 150
    for command in ("bash scripts/demo.sh", "bash scripts/test.sh"):
        assert f"\n{command}" in readme and (REPO / command.split()[1]).is_file(), command
    targets = re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", readme)
    assert targets, "the README links into the documentation"
    assert [target for target in targets if not (REPO / target).exists()] == []
