"""scenarios: scenario files, runs, metrics, rerun recordings, paper reproductions and the CLI.

The only package that imports the other three.
"""
