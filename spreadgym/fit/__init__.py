"""Fitting a scene to a measured tray test (`spreadgym fit`), with 90 % intervals.

One job per module: `trays` reads the tray file, `space` the fitted keys and their
ranges, `likelihood` turns simulated patterns into the catch-noise likelihood,
`optimise` finds the estimate, `uncertainty` the profile-likelihood intervals and the
identifiability report, `outputs` the JSON, files and pictures, `synthetic` makes
tray tests at known parameters. The model does not know it is being fitted: everything
here goes through `spread.batch.run_batch` on ordinary scenes.
"""
