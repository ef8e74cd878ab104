"""The bundled demo SUT: a small autonomous-driving stack on Zenoh, one process per module.

``simulator`` (the world) → ``prediction`` → ``planning`` (a thin wrapper
around the pure ``planner_core.Planner``) → ``control`` → back to the
simulator, JSON messages on plain ``demo/…`` keys. Its spec is
``astaa_deft/data/specs/demo_av.yaml``; README.md here explains the modules,
the scenarios and the seeded robustness defects.
"""
