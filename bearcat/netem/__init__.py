"""Network and sensor impairment models, named profiles and the bus shim that applies them."""
