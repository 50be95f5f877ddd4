"""The guidance service and its advisors.

The service (``service``) sends each phone its guidance from the latest
fixes (``fixes``); an advisor adds the solver's part for an aided agent:
``advisor(agent, fixes, now)`` returns the fields of its ``Guidance`` and
``advisor.state(game_state)`` follows the referee (the flag taken moves a
game to its next stage). One advisor per game: capture-the-flag (``ctf``),
cooperative pursuit (``pursuit``), open-loop reach-avoid (``open_loop``) and
capture-the-flag under limited visibility (``search``). Regions and lines
go out as ``[lon, lat]`` rings (``outlines``).
"""

from bearcat.agents.ground_station.guidance.ctf import CtfAdvisor
from bearcat.agents.ground_station.guidance.open_loop import ReachAvoidAdvisor
from bearcat.agents.ground_station.guidance.pursuit import PursuitAdvisor
from bearcat.agents.ground_station.guidance.search import SearchAdvisor
from bearcat.agents.ground_station.guidance.service import GuidanceService

__all__ = ["CtfAdvisor", "GuidanceService", "PursuitAdvisor", "ReachAvoidAdvisor", "SearchAdvisor"]
