"""Learning curves: metrics rows in ``curve.csv`` and their plot, ``curve.png``."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Sequence


class LearningCurve:
    """Rows of metrics appended to ``curve.csv`` as training goes, plotted to ``curve.png`` on ``plot()``."""

    def __init__(self, run_dir: Path, fields: Sequence[str]):
        self.path = Path(run_dir) / "curve.csv"
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.fields = list(fields)
        with self.path.open("w", newline="") as f:
            csv.writer(f).writerow(self.fields)

    def log(self, **row) -> None:
        with self.path.open("a", newline="") as f:
            csv.writer(f).writerow([row.get(k, "") for k in self.fields])

    def plot(self, x: str, ys: Sequence[str], title: str) -> Path:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        rows = list(csv.DictReader(self.path.open()))
        figure, axes = plt.subplots(len(ys), 1, figsize=(6, 2.4 * len(ys)), sharex=True, squeeze=False)
        for axis, y in zip(axes[:, 0], ys):
            points = [(float(r[x]), float(r[y])) for r in rows if r.get(y) not in ("", None)]
            if points:
                axis.plot(*zip(*points), marker=".")
            axis.set_ylabel(y)
            axis.grid(alpha=0.3)
        axes[-1, 0].set_xlabel(x)
        axes[0, 0].set_title(title)
        figure.tight_layout()
        out = self.path.with_suffix(".png")
        figure.savefig(out, dpi=100)
        plt.close(figure)
        return out

