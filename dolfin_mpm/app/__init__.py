"""Scenario files and the command line: validation, runs with events, output and checkpoints, regions."""
