"""Batches of simulated games: the thesis studies (``thesis``), independent
trials (``batch``), human trials and the pursuit comparison of thesis 5.3.2."""
