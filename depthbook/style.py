"""The style of every plot of the book: each filter's label, colour and line style, the sizes.

Recommended import: ``from depthbook import style``.

:data:`STYLE` is one vocabulary for every plot, from the registry
:data:`depthcore.registry.filters.FILTERS`; :func:`subplots` makes a figure in the
book's style, at most :data:`WIDTH` inches wide, at :data:`DPI`, with no
font smaller than :data:`MIN_FONT` points where the chapters set one.
"""

from __future__ import annotations

import numpy as np

from depthcore.registry.filters import FILTERS

#: One vocabulary for every plot, the label, colour and line style of each filter,
#: from the registry :data:`depthcore.registry.filters.FILTERS`.
STYLE = {name: f.plot_style for name, f in FILTERS.items()}


#: The widest figure of the book's plot style, in inches. Every figure is at
#: most ``WIDTH`` inches wide, rendered at ``DPI`` dots per inch (Jupyter and
#: the book draw the PNG at ``fig.dpi``), with no text smaller than ``MIN_FONT``
#: points (tick labels, legends and titles at matplotlib's 10 points unless
#: stated). The PDF prints a figure at most 0.85 of its text's width and 0.7 of its
#: height (``_config.yml``), so one ``WIDTH`` inches wide shrinks to 0.79 of its size;
#: every figure is drawn short enough that its smallest text prints at 6.8 points or
#: more (``tests/book/test_pdf.py`` checks each image of the built book).
WIDTH = 7.2


#: The dots per inch of every figure's PNG.
DPI = 150


#: The smallest font size of any text of a figure, in points.
MIN_FONT = 9.0


def subplots(nrows: int = 1, ncols: int = 1, *, figsize, **kwargs):
    """``plt.subplots`` in the book's style: constrained layout at :data:`DPI`."""
    import matplotlib.pyplot as plt

    if figsize[0] > WIDTH + 1e-9:
        raise ValueError(f"figsize: at most {WIDTH} inches wide, got {figsize[0]}")
    return plt.subplots(nrows, ncols, figsize=figsize, dpi=DPI, layout="constrained", **kwargs)


def legend_below(fig, axes, ncol: int) -> None:
    """One legend for a figure, below its plots: each label of ``axes`` once, in order.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        From :func:`subplots`, whose constrained layout keeps the legend outside the plots.
    axes : sequence of matplotlib.axes.Axes
        The plots whose labelled lines the legend names.
    ncol : int
        Columns of the legend.
    """
    handles, labels = [], []
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            if label not in labels:
                handles.append(handle)
                labels.append(label)
    fig.legend(
        handles, labels, loc="outside lower center", ncol=ncol, frameon=False, fontsize=MIN_FONT
    )


def log_bars(y, se):
    """Bars of two standard errors either side of ``y`` for a log axis, shape (2, n).

    The lower bar stops at a tenth of its point, short of zero, where a log axis
    cannot go; the upper is two standard errors. For ``errorbar(..., yerr=...)``.

    Parameters
    ----------
    y, se : array_like, shape (n,)
        The values, positive, and their standard errors.
    """
    y, se = np.asarray(y, dtype=float), np.asarray(se, dtype=float)
    return np.vstack([np.minimum(2 * se, 0.9 * y), 2 * se])


def reference_rate(ax, x, y, label: str) -> None:
    """A broad grey line behind the data, on log-log axes: the rate a Monte Carlo error follows.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    x, y : array_like, shape (n,)
        Numbers of draws and the error expected with them, e.g. ``sd / sqrt(x)``.
    label : str
    """
    ax.plot(x, y, color="0.7", linewidth=3, alpha=0.6, zorder=0, label=label)
    ax.set_xscale("log")
    ax.set_yscale("log")
