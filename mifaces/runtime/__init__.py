"""Running mifaces: the libLLVM Dr.Jit loads, the Mitsuba variant, progress, Dr.Jit arrays and how a fit ended."""
