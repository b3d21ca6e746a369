"""Sensing: landing pads, cameras (virtual and real), marker detection, IR-LOCK, fusion."""
