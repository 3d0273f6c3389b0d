"""What to change after a tray test (`spreadgym advise`): the fit of the material to the test, the chart's
robust settings search on the fitted model, and the expected CV before and after (`run`); how good the advice
is, on synthetic tray tests against the full model (`bench`)."""

from spreadgym.agents.advise.run import Advice, advice_payload, advise

__all__ = ["Advice", "advise", "advice_payload"]
