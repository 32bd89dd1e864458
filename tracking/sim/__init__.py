"""The simulated patient studio: body model, motions, virtual cameras and renderer."""
