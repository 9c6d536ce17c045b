"""Generation of motion parameters from statistical models (MLPG with global variance: :mod:`.mlpg`)."""
