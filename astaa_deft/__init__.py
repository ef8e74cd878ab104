"""astaa-deft: robustness and determinism testing for robot software on a Zenoh bus."""

__version__ = "0.1.0"
