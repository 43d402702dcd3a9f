"""The class's side: the LMS's names and roster, collecting hand-ins, export and return, the hub's exchange."""
