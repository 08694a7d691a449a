"""Dataset generator: the bpy render loop that feeds the event simulator (arrives with the dataset issue)."""
