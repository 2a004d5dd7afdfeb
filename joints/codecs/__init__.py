"""Codecs: pure bytes <-> frozen message dataclasses. No I/O, no clock, no threads (sans-I/O)."""
