"""What a student sees: the feedback notebook and its HTML page, without the hidden tests.

``scrub`` takes out what a student must not see (and draws nothing); ``notebook`` builds the
feedback notebook from it, with ``plot``'s verdict plots; ``exporter`` writes the page
(``mathml`` for its maths, ``page`` for nbconvert's last step, faster); ``scores`` writes every
page from the gradebook's numbers (one number everywhere).
"""
