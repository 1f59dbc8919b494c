"""Pure computation: numpy arrays in, plain data out. No zenoh, no HTTP, no files."""
