"""What every method is measured against: scenes with supersampled truth, metrics, the FXAA baseline. Imports the library, never the other way round."""
