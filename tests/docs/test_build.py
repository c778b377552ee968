"""The documentation site builds, with warnings as errors, as a fresh clone would build it."""

import os
import subprocess
import sys

from tests.docs.pages import REPO


def test_the_site_builds_in_strict_mode(tmp_path):
    site = tmp_path / "site"
    environment = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}  # Material's banner, not a build warning
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
        cwd=REPO, env=environment, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "WARNING" not in result.stderr, result.stderr[-3000:]
    for page in ("index.html", "scenarios/town/index.html", "api/envs/index.html", "cli/index.html"):
        assert (site / page).is_file(), page
    # the notebooks are rendered (not executed: they are stored without outputs)
    assert (site / "notebooks" / "01_scenarios_and_sensors" / "index.html").is_file()
    # the generated tables were filled in
    town = (site / "scenarios" / "town" / "index.html").read_text()
    assert "<!-- drivelab:" not in town and "fixed_routes" in town
