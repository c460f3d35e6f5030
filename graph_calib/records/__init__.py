"""Records and their preparation: the experiment data classes, plausibility, the grade chosen from a record, the problem built from it."""
