"""Fixture-loading planning: the coarse contact-state search and the fine per-transition plans."""
