"""Light fields: the 4-D container, camera-array and lenslet import,
refocusing (shift-and-add, Fourier slice) and light-slab rendering."""
