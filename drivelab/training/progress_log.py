"""A run's SB3 logger: ``progress.csv`` and TensorBoard events that a resume continues.

SB3's ``configure`` opens progress.csv with ``"w+"``, emptying it, so a resume used to set the
old file aside (``progress-<steps>.csv``) and start a new one. Here the CSV is opened for
appending, its columns read from its header; ``resume_state.plan_truncation`` has cut it back to
the checkpoint's step first, so the resumed rows follow on as the rows of the run never stopped
(``agents/sb3.py``'s ``RolloutLogs`` logs on-policy rows by their step). TensorBoard keeps each
process's events in a file of its own; a resumed run's writer starts with ``purge_step`` one past
the checkpoint, and TensorBoard then hides what the stopped process had logged after it.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

from stable_baselines3.common.logger import CSVOutputFormat, Logger, TensorBoardOutputFormat


class ContinuedCSV(CSVOutputFormat):
    """SB3's CSV output appending to ``path`` (created if missing; never through a link), with
    the columns of its header; a key that is new adds a column, as SB3's does."""

    def __init__(self, path: Path) -> None:
        descriptor = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
        self.file = os.fdopen(descriptor, "r+")
        header = self.file.readline()
        self.keys = next(csv.reader([header])) if header.strip() else []
        self.file.seek(0, os.SEEK_END)
        self.separator, self.quotechar = ",", '"'


class ContinuedTensorBoard(TensorBoardOutputFormat):
    """SB3's TensorBoard output whose writer hides the events logged at ``purge_step`` or later
    by an earlier writer of the folder (a stopped process's, past its checkpoint)."""

    def __init__(self, folder: Path, purge_step: int) -> None:
        from torch.utils.tensorboard import SummaryWriter

        self.writer = SummaryWriter(log_dir=str(folder), purge_step=purge_step)
        self._is_closed = False


def run_logger(run_dir: Path, resumed_at: int | None = None) -> Logger:
    """The logger of a run directory: ``progress.csv`` (continued) and TensorBoard events; with
    ``resumed_at``, the checkpoint's step a resume starts from."""
    tensorboard = (
        TensorBoardOutputFormat(str(run_dir))
        if resumed_at is None
        else ContinuedTensorBoard(run_dir, resumed_at + 1)
    )
    return Logger(folder=str(run_dir), output_formats=[ContinuedCSV(run_dir / "progress.csv"), tensorboard])
