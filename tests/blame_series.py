"""Runs as blame compares them, crafted: channels at 10 Hz, one value per 0.1 s (tests of campaign blame)."""

from __future__ import annotations

from astaa_deft.orchestration.campaign.blame import RunSeries, bin_features


def series(channel_values: dict[str, list[float | None]], mutated_at: int | None = None,
           mutated: tuple[str, ...] = ()) -> RunSeries:
    """Channels at 10 Hz, one value per 0.1 s (None: no message then), as ``{"v": value}`` messages."""
    bins = {}
    for channel, values in channel_values.items():
        bins[channel] = bin_features((0.1 * i + 0.01, {"v": v}) for i, v in enumerate(values) if v is not None)
    return RunSeries(bins, mutated_at, mutated)
