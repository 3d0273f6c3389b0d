"""`spreadgym serve`: a local web app (FastAPI) with the pattern page and the chart page."""
