"""Dataset builds: a source read, built into CCS surfaces, turned into store rows and saved with its labels."""
