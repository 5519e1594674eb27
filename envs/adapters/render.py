"""Top-down view of one swarmloc episode (matplotlib, Agg offscreen or a window).

Anchors are black triangles, landmarks grey squares, true UAV positions filled circles,
estimates crosses joined to their truth by a thin line (the error). Every valid channel
of every UAV is a line from the UAV to what it measures (anchor, neighbour, landmark),
coloured by the trust applied at the last update (red 0 → green 1); a GPS channel is a
ring around the UAV in the same colours. The view is the x–y plane (ENU, metres).
"""

from __future__ import annotations

import numpy as np

from swarmloc.envs.tasks.channels import ANCHOR, GPS, LANDMARK, TDOA, ChannelLayout, tdoa_pair

#: frame size in pixels (width, height) of ``rgb_array`` renders
FRAME_SIZE = (480, 480)
_NON_INTERACTIVE = {"agg", "pdf", "ps", "svg", "pgf", "cairo", "template", "module://matplotlib_inline.backend_inline"}


class TopDownRenderer:
    """Draws frames of one environment; holds one figure until ``close``.

    Args:
        layout: the task's channel layout.
        anchors: ``(A, 3)`` anchor positions [m].
        landmarks: ``(M, 3)`` landmark positions [m].
        title: shown above the plot (the task ID).
        human: draw into a window when an interactive matplotlib backend (a display)
            exists; otherwise frames are drawn offscreen and nothing is shown.
    """

    def __init__(self, layout: ChannelLayout, anchors: np.ndarray, landmarks: np.ndarray, title: str,
                 human: bool = False):
        from matplotlib.figure import Figure

        self.layout, self.anchors, self.landmarks, self.title = layout, anchors, landmarks, title
        self._window = False
        if human:
            import matplotlib.pyplot as plt

            if plt.get_backend().lower() not in _NON_INTERACTIVE:
                self.fig = plt.figure(figsize=(FRAME_SIZE[0] / 100, FRAME_SIZE[1] / 100), dpi=100)
                self._window = True
        if not self._window:
            from matplotlib.backends.backend_agg import FigureCanvasAgg

            self.fig = Figure(figsize=(FRAME_SIZE[0] / 100, FRAME_SIZE[1] / 100), dpi=100)
            FigureCanvasAgg(self.fig)
        self.ax = self.fig.add_subplot(1, 1, 1)

    def draw(self, truth: np.ndarray, estimate: np.ndarray, applied: np.ndarray, valid: np.ndarray,
             time_s: float) -> np.ndarray:
        """Draw one frame and return it as RGB ``(H, W, 3)`` uint8.

        Args:
            truth, estimate: ``(N, 3)`` true and estimated positions [m].
            applied: ``(N, L)`` trust applied at the last update.
            valid: ``(N, L)`` channels that carried a measurement.
            time_s: episode time [s] for the title.
        """
        from matplotlib import colormaps
        from matplotlib.collections import LineCollection

        ax, lay = self.ax, self.layout
        ax.clear()
        cmap = colormaps["RdYlGn"]
        segments, colours, rings = [], [], []
        for i, l in zip(*np.nonzero(valid)):
            kind, target = lay.kind[i, l], lay.target[i, l]
            if kind == GPS:
                rings.append((truth[i, :2], applied[i, l]))
                continue
            if kind == TDOA:  # a range difference: drawn to the pair's second anchor (z = ‖p − a_j‖ − ‖p − a_i‖)
                end = self.anchors[tdoa_pair(int(target), len(self.anchors))[1]]
            else:
                end = self.anchors[target] if kind == ANCHOR else self.landmarks[target] if kind == LANDMARK \
                    else truth[target]
            segments.append((truth[i, :2], end[:2]))
            colours.append(cmap(float(applied[i, l])))
        if segments:
            ax.add_collection(LineCollection(segments, colors=colours, linewidths=1.0, alpha=0.7, zorder=1))
        for centre, trust in rings:
            ax.scatter(*centre, s=300, facecolors="none", edgecolors=[cmap(float(trust))], linewidths=1.5, zorder=1)
        if len(self.anchors):
            ax.scatter(self.anchors[:, 0], self.anchors[:, 1], marker="^", c="black", s=60, label="anchor", zorder=3)
        if len(self.landmarks):
            ax.scatter(self.landmarks[:, 0], self.landmarks[:, 1], marker="s", c="grey", s=20, label="landmark",
                       zorder=2)
        for i in range(truth.shape[0]):
            ax.plot([truth[i, 0], estimate[i, 0]], [truth[i, 1], estimate[i, 1]], c="tab:blue", lw=0.8, zorder=3)
        ax.scatter(truth[:, 0], truth[:, 1], c="tab:blue", s=40, label="truth", zorder=4)
        ax.scatter(estimate[:, 0], estimate[:, 1], marker="x", c="tab:red", s=40, label="estimate", zorder=5)
        points = np.concatenate([truth[:, :2], estimate[:, :2], self.anchors[:, :2], self.landmarks[:, :2]])
        lo, hi = points.min(axis=0), points.max(axis=0)
        centre, half = (lo + hi) / 2, max(float((hi - lo).max()) / 2 * 1.1, 2.0)
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_title(f"{self.title}  t = {time_s:.1f} s", fontsize=9)
        ax.legend(loc="best", fontsize=7, framealpha=0.6)
        self.fig.tight_layout()
        self.fig.canvas.draw()
        if self._window:
            self.fig.canvas.flush_events()
            import matplotlib.pyplot as plt

            plt.show(block=False)
        return np.asarray(self.fig.canvas.buffer_rgba())[..., :3].copy()

    def close(self) -> None:
        """Release the figure (idempotent)."""
        if self.fig is None:
            return
        if self._window:
            import matplotlib.pyplot as plt

            plt.close(self.fig)
        self.fig = None


class FirstEpisodeView:
    """Top-down view of a batch's first episode, created on first use.

    Shared by the Gymnasium and PettingZoo envs: both show episode 0 of their
    ``TrustEnvBatch``. ``frame()`` draws the latest update; ``close()`` is idempotent.

    Args:
        batch: the env's ``TrustEnvBatch``.
        task_id: title of the view.
        human: draw in a window (where a display exists) instead of offscreen only.
    """

    def __init__(self, batch, task_id: str, human: bool):
        self._batch = batch
        self._task_id = task_id
        self._human = human
        self._renderer: TopDownRenderer | None = None

    def frame(self) -> np.ndarray:
        """The ``(480, 480, 3)`` uint8 frame of episode 0 at its latest update."""
        if self._renderer is None:
            w = self._batch.core.world
            self._renderer = TopDownRenderer(self._batch.layout, w.anchors, w.landmarks, self._task_id,
                                             human=self._human)
        o = self._batch.last
        return self._renderer.draw(o.truth[0], o.estimate[0], o.applied[0], o.valid[0],
                                   float(o.steps[0]) * self._batch.spec.dt)

    def close(self) -> None:
        """Release the renderer (harmless when called again)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
