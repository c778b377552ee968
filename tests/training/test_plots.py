"""The run and comparison plots: written as PNG without touching the caller's matplotlib backend."""

import subprocess
import sys


def test_plot_modules_leave_the_backend_alone():
    # a notebook (inline backend) that trains a run must still show its own figures afterwards
    code = (
        "import matplotlib; matplotlib.use('svg');"
        "import drivelab.training.plots, drivelab.training.compare_plots, drivelab.agents.qlearning_plots;"
        "print(matplotlib.get_backend())"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "svg"
