"""The zoo of module behaviours: small modules on the bus, each one combination of behaviours.

DeFT is developed against the whole zoo, not one stack. Importable from the
tests (``tests/`` is on ``sys.path`` under pytest) and from benchmarks
(``sys.path.insert(0, "tests")``). The stable API:

    from zoo import Member, AXES, MEMBERS, SHORT, by_name, short      # descriptions and the catalogue
    from zoo import write_member, Stack                               # a member as a runnable stack
    from zoo import record                                            # run it on the bus, recorded
    from zoo import plain_replay, Floor, output_key                   # the plain-replay floor
    from zoo import frame_truth                                       # which inputs an output used

See tests/zoo/README.md.
"""

from zoo.floor import Floor, output_key, plain_replay
from zoo.generate import MODULE, Stack, write_member
from zoo.member import AXES, INPUTS, OUTPUT, Member
from zoo.members import MEMBERS, MPC, NODE_FRAME_ID, SHORT, SLOW_PLANNER, by_name, short
from zoo.record import record
from zoo.truth import frame_truth

__all__ = ["AXES", "Floor", "INPUTS", "MEMBERS", "MODULE", "MPC", "Member", "NODE_FRAME_ID", "OUTPUT", "SHORT",
           "SLOW_PLANNER",
           "Stack", "by_name", "frame_truth", "output_key", "plain_replay", "record", "short", "write_member"]
