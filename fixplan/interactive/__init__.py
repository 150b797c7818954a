"""Interactive haptic planning: a person (or a device bridge) drives the part and feels the contacts.

- :mod:`.session` — the 1 kHz loop around the engine, the guidance thread, the contact-state record;
- :mod:`.handles` — the device side: the viser gizmo, the UDP bridge, a SpaceMouse;
- :mod:`.protocol` — the UDP bridge's datagrams;
- :mod:`.device_sim` — ``fixplan device-sim``, the bridge's reference client;
- :mod:`.record` — a session as a plan file, and its re-run in the loop (``fixplan verify``);
- :mod:`.app` — the viser web app (``fixplan haptic``).

viser is imported only by :mod:`.app`.
"""
