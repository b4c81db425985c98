"""Preset scenario files (``*.toml``), listed by ``insnav scenarios``."""
