"""The work cell: its model and the reading and validation of the cell file."""
