"""Scripted experts that make the course's demonstrations (no download needed).

- ``pusht_planner``: the PushT push planner and ``collect_dataset`` (``coursekit collect pusht``),
  built from ``pusht_push_model`` (where a push moves the T), ``pusht_routes`` (how the pusher
  gets round the T) and ``pusht_clearance`` (distances to the T).
- ``pusht_two_ways``: which starts make the expert toss its coin between the two ways round the T
  (``first_decision``), and which way a path of pusher targets goes (``path_side``).
- ``aloha_scripted``: the ALOHA arm pair's scripted experts.

Modules load on demand (``from coursekit.experts.pusht_planner import PushTExpert``).
"""
