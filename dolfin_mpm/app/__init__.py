"""Scenario files and the command line: validation, the run driver, progress, regions."""
