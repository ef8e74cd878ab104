"""Everything that touches the live Zenoh bus: session configs, the launcher, the proxy."""
