"""The teacher's view of a class after grading: where it stands, why it fails, which submissions are too alike."""
