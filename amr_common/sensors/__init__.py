"""Sensor models of amr_common."""
