"""Worlds and maps of amr_common."""
