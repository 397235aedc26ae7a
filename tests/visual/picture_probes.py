"""Looking into a rendered picture: where a point of the network is drawn and which colour a tension gets,
computed independently of visual.py's own colour norm."""
from __future__ import annotations

import numpy as np

from linknet_core import visual

CRAFTED_LIMIT = 10.0  # N: the crafted motion's tensions are drawn on a colour scale from -10 to 10 N


def render(picture: visual.NetworkFigure) -> np.ndarray:
    """The picture as the writers draw it, (height, width, 4) uint8."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(picture.fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba()).copy()


def pixel_of(picture: visual.NetworkFigure, point) -> tuple[int, int]:
    """(row, column) of the image pixel where a point (x, y, z, m) is drawn; call after render()."""
    if picture.view == "3d":
        from mpl_toolkits.mplot3d import proj3d

        x, y, _ = proj3d.proj_transform(*point, picture.ax.get_proj())
    else:
        a, b = visual.PLANES[picture.view]
        x, y = point[a], point[b]
    column, height_up = picture.ax.transData.transform((x, y))
    return int(round(picture.fig.bbox.height - height_up - 0.5)), int(round(column - 0.5))


def tension_rgb(T: float, limit: float, cmap: str = visual.DEFAULT_CMAP) -> np.ndarray:
    """The 0-255 colour of tension T on a scale from -limit to limit, computed independently of visual.py's norm."""
    import matplotlib

    return np.round(255 * np.array(matplotlib.colormaps[cmap](0.5 + 0.5 * T / limit)[:3]))
