"""Input and output: shape files, CAD import, the input deck and the result writers."""
