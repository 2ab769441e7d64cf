"""Evaluation: the method paper's metrics, their time series, plots and reports."""
