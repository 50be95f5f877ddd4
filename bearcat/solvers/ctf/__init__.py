"""The 1 vs 1 capture-the-flag game (thesis 3.1, 3.3): its winning sets, the queries guidance asks of them
(slices, headings, values), games played out, and the worst cases and quantiles of uncertain positions."""
