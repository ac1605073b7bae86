"""mbs.app -- the application layer on top of the modeling core.

``cli`` (``python -m mbs`` / the ``mbs`` console script), ``scene`` (TOML scene
files), ``runner`` (a scene -> simulate -> result.json and figures), ``results``
(result.json), ``figures`` and ``frame_figures`` (paper Figs. 2, 3, 5; frame regions),
``sampling`` (the DOP853 sampling oracle: the one home of the sampled points and
trajectories of the app, the tests and the benchmarks), ``demo`` and ``bench``. This
package may import :mod:`models` and the rest of :mod:`mbs`; the modeling core
(``mbs/*.py``) never imports it (nor :mod:`models`, which it finds through the
entry-point group ``mbs.models``).
"""
