"""Pictures for people: report figures (metrics over time, flight paths, layer images), the layer and
decision figures of `layerpilot layers render`, the map of `layerpilot map scan`, and the
`layerpilot sim preview` / `layerpilot depth preview` panels.

matplotlib with the Agg backend only (no display needed). The algorithm packages never import
this package: it sits at the edge, next to the reports (``layerpilot.eval.report``, ``summary``).
"""
