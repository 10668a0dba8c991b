"""Helpers for tests that drive the chess FMUs through fmpy (via robofmu.system.fmu.Block)."""
from __future__ import annotations

from robofmu.system.fmu import Block


def open_block(fmu_dir, block, name=None, parameters=None, start_time=0.0):
    """Instantiate and initialize ``fmu_dir/<block>.fmu``."""
    b = Block(fmu_dir / f"{block}.fmu", name or block)
    b.initialize(start_time, parameters)
    return b


class ChessLoop:
    """trajectory -> ik -> controller -> plant, fed back; outputs in dependency order
    (Gauss-Seidel at each communication point, no step of delay), then every block steps."""

    def __init__(self, fmu_dir, controller=None, plant=None):
        self.tr = open_block(fmu_dir, "trajectory")
        self.ik = open_block(fmu_dir, "ik")
        self.ct = open_block(fmu_dir, "controller", parameters=controller)
        self.pl = open_block(fmu_dir, "plant", parameters=plant)
        self.blocks = [self.tr, self.ik, self.ct, self.pl]
        self.v_tr_out = self.tr.vrs("x_ref", "xd_ref", "xdd_ref")
        self.v_ik_in = self.ik.vrs("x_ref", "xd_ref", "xdd_ref")
        self.v_ik_out = self.ik.vrs("q_ref", "qd_ref", "qdd_ref")
        self.v_ct_in = self.ct.vrs("q_ref", "qd_ref", "qdd_ref", "q", "qd")
        self.v_ct_out = self.ct.vrs("tau")
        self.v_pl_out = self.pl.vrs("q", "qd")
        self.v_pl_in = self.pl.vrs("tau")
        self.t = 0.0

    def exchange(self):
        """Evaluate the diagram at the current point; returns (x_ref, q_ref.., q/qd, tau)."""
        x = self.tr.get_real(self.v_tr_out)
        grip = self.tr.get("grip")
        self.ik.set_real(self.v_ik_in, x)
        qref = self.ik.get_real(self.v_ik_out)
        y = self.pl.get_real(self.v_pl_out)
        self.ct.set_real(self.v_ct_in, qref + y)
        self.ct.set("grip", grip)
        tau = self.ct.get_real(self.v_ct_out)
        self.pl.set_real(self.v_pl_in, tau)
        self.pl.set("grip", grip)
        return x, qref, y, tau

    def step(self, h):
        out = self.exchange()
        for b in self.blocks:
            b.do_step(self.t, h)
        self.t += h
        return out

    def close(self):
        for b in self.blocks:
            b.close()
