"""Figures from arrays (matplotlib Figure API, off-screen): sample panels and predictions,
pictures of maps, contact sheets."""
