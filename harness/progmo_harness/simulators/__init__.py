"""Simulator back-ends of the checks: MuJoCo 4.0 (``mujoco_sim``) and Pinocchio 4.1
(``pinocchio_sim``), with the shared coordinate maps and metrics in ``replay``.

Each back-end is a class built from a scene's export (document + report) with:

* ``model_terms(t, q, v) -> (M, rhs)`` in OUR coordinates, ``rhs`` = every non-control generalized
  force the simulator's equations contain (``-bias + passive + harness forces``), to compare with
  our ``G + Q``;
* ``instant_u(t, q, v, a, B, gamma) -> u`` the control force the simulator itself derives;
* ``replay(ref, record_frames) -> Replay`` open-loop replay of ``ref.u`` (u at each RK4 stage).
"""


class BlowUp(RuntimeError):
    """The replay produced a non-finite state or an absurd acceleration."""

    def __init__(self, time: float, what: str):
        super().__init__(f"simulator blew up at t = {time:.6g}: {what}")
        self.time = time
