"""Reproduction of the paper: comparison rows, figures and the Markdown report."""
