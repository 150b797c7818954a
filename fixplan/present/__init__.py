"""Presentation: what fixplan shows people, apart from what it computes.

- :mod:`.plots` — the plan's figure over time (forces, gaps, wrench, contact states; matplotlib);
- :mod:`.maps` — the jamming diagram of a :class:`~fixplan.mapping.JammingMap` (matplotlib, CSV);
- :mod:`.replay`, :mod:`.meshes`, :mod:`.scene`, :mod:`.page` — the scene page of ``fixplan
  view``: what is replayed (a plan's :class:`~fixplan.planner.plan.Timeline`, or the start pose at
  rest), the shapes' meshes, the plotly figure, the self-contained HTML page;
- :mod:`.report` — the Markdown report of a plan (``fixplan solve --report``);
- :mod:`.browser` — headless Chromium for the page's test and the gallery
  (``python -m fixplan.present.browser page.html shot.png``).

The modules draw results the library computed (a :class:`~fixplan.planner.plan.Plan`, a jamming
map, a fixture); they compute no mechanics of their own. matplotlib, plotly and Playwright are
imported inside the functions that need them, so importing a module here stays light.
"""
