"""Learning algorithms and shipped policies for tissue retraction."""
