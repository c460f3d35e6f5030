"""Predicted accuracy of a record or program, and the shortest program meeting targets."""
