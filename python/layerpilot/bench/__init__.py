"""`layerpilot bench map|decide|depth|sim|bus`: every speed claim measured against its reference
(OctoMap itself, OpenCV, a bare Zenoh queryable) in the same run, printing a ratio.

One module per benchmark; the command line is ``layerpilot.cli.bench``. Tests check behaviour,
benchmarks check speed.
"""
