"""What every command writes and shows: run folders (claim, atomic writes, the one metadata
writer), progress, figures and the report (plots, animations, templates, robot export).
Knows file formats, not how results were computed.
"""
