"""window tasks of a fit in windows: jobs.parent_id, window_index, phase (and the state 'waiting')

Revision ID: 0003
Revises: 0002
"""

import sqlalchemy as sa
from alembic import op

revision = '0003'
down_revision = '0002'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("jobs", schema=None) as batch_op:
        batch_op.add_column(sa.Column("parent_id", sa.String(length=40), nullable=True))
        batch_op.add_column(sa.Column("window_index", sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column("phase", sa.String(length=20), nullable=True))
        batch_op.create_index("ix_jobs_parent", ["parent_id", "phase"], unique=False)


def downgrade() -> None:
    with op.batch_alter_table("jobs", schema=None) as batch_op:
        batch_op.drop_index("ix_jobs_parent")
        batch_op.drop_column("phase")
        batch_op.drop_column("window_index")
        batch_op.drop_column("parent_id")
