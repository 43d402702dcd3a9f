"""What a student sees: the feedback notebook and its HTML page, without the hidden tests."""
