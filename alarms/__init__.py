"""Alarm rules and the alarm lifecycle."""
