"""run estimates: external algorithms' trajectories scored on a run's own relations

Revision ID: 0003
Revises: 0002
Create Date: 2026-12-02 01:50:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "run_estimates",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("owner_id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=40), nullable=False),
        sa.Column("source", sa.String(length=200), nullable=False),
        sa.Column("n_poses", sa.Integer(), nullable=False),
        sa.Column("metrics", sa.JSON(), nullable=False),
        sa.Column("b_mean_t", sa.Float(), nullable=True),
        sa.Column("b_mean_r", sa.Float(), nullable=True),
        sa.Column("report_dir", sa.Text(), nullable=True),
        sa.Column("data", sa.LargeBinary(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(["run_id"], ["runs.id"], name=op.f("fk_run_estimates_run_id_runs")),
        sa.ForeignKeyConstraint(
            ["owner_id"], ["users.id"], name=op.f("fk_run_estimates_owner_id_users")
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_run_estimates")),
        sa.UniqueConstraint("run_id", "name", name=op.f("uq_run_estimates_run_id")),
    )
    with op.batch_alter_table("run_estimates", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_run_estimates_run_id"), ["run_id"], unique=False)
        batch_op.create_index(batch_op.f("ix_run_estimates_owner_id"), ["owner_id"], unique=False)


def downgrade() -> None:
    with op.batch_alter_table("run_estimates", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_run_estimates_owner_id"))
        batch_op.drop_index(batch_op.f("ix_run_estimates_run_id"))
    op.drop_table("run_estimates")
