"""One module per figure of the paper: ``compute(...)`` returns the data, ``plot(data, ax=None)`` draws it.

* :mod:`~granchain.paper.figures.fig1` - averaged velocity of the large granules vs time (N = 11);
* :mod:`~granchain.paper.figures.fig2` - amplitude decay vs k with the stretched-exponential fit (N = 26), inset vs time;
* :mod:`~granchain.paper.figures.fig3` - arrival time vs k with the linear fit and the BCA slope S (N = 26);
* :mod:`~granchain.paper.figures.fig4` - arrival-time distributions at granule N-1 (N = 6, 11, 16, 26) vs the BCA, and d vs N.
"""

from . import fig1, fig2, fig3, fig4
from ._style import save

__all__ = ["fig1", "fig2", "fig3", "fig4", "save"]
