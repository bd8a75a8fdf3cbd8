"""The plug-in contract of amr_common."""
