"""A run's SB3 logger: ``progress.csv`` and TensorBoard events that a resume continues.

The CSV is opened for appending (SB3's ``configure`` would empty it), its columns read from its
header, after ``resume_state.plan_truncation`` cut it back to the checkpoint's step. A resumed run's
TensorBoard writer starts with ``purge_step`` one past the checkpoint, which hides what the stopped
process logged after it."""

from __future__ import annotations

import csv
import os
from pathlib import Path

from stable_baselines3.common.logger import CSVOutputFormat, Logger, TensorBoardOutputFormat


class ContinuedCSV(CSVOutputFormat):
    """SB3's CSV output appending to ``path`` (never through a link), with the columns of its header."""

    def __init__(self, path: Path) -> None:
        descriptor = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
        self.file = os.fdopen(descriptor, "r+")
        header = self.file.readline()
        self.keys = next(csv.reader([header])) if header.strip() else []
        self.file.seek(0, os.SEEK_END)
        self.separator, self.quotechar = ",", '"'


class ContinuedTensorBoard(TensorBoardOutputFormat):
    """SB3's TensorBoard output hiding the events an earlier writer logged at ``purge_step`` or later."""

    def __init__(self, folder: Path, purge_step: int) -> None:
        from torch.utils.tensorboard import SummaryWriter

        self.writer = SummaryWriter(log_dir=str(folder), purge_step=purge_step)
        self._is_closed = False


def run_logger(run_dir: Path, resumed_at: int | None = None) -> Logger:
    """A run's logger: ``progress.csv`` (continued) and TensorBoard; ``resumed_at``: a resume's step."""
    tensorboard = (
        TensorBoardOutputFormat(str(run_dir))
        if resumed_at is None
        else ContinuedTensorBoard(run_dir, resumed_at + 1)
    )
    return Logger(folder=str(run_dir), output_formats=[ContinuedCSV(run_dir / "progress.csv"), tensorboard])
