"""The live view and run recordings in Rerun: a mission's map, layers, pose, path, decisions and metrics.

Imported only by what asks for a view (`layerpilot view`, `demo --view`, the .rrd of demo and study
runs): a mission without it never loads rerun.
"""
