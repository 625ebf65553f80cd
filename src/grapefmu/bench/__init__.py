"""`grapefmu bench`: speed against error on hard scenes, side by side with peer methods."""
