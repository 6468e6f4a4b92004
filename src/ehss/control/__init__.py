"""Digital controllers of the three loops and their default tunings."""
