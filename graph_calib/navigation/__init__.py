"""Navigation primitives: rotations, strapdown integration, static detection, alignment."""
