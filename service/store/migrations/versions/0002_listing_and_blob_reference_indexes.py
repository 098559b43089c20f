"""indexes for cursor-paginated listing and blob reference checks (jobs may now be 'cancelled')

Revision ID: 0002
Revises: 0001
"""

from alembic import op

revision = '0002'
down_revision = '0001'
branch_labels = None
depends_on = None

INDEXES = [
    ("meshes", "ix_meshes_list", ["tenant_id", "created_at", "id"]),
    ("meshes", "ix_meshes_blob_key", ["blob_key"]),
    ("poses", "ix_poses_list", ["tenant_id", "created_at", "id"]),
    ("poses", "ix_poses_blob_key", ["blob_key"]),
    ("clips", "ix_clips_list", ["tenant_id", "created_at", "id"]),
    ("clips", "ix_clips_topology_key", ["topology_key"]),
    ("clips", "ix_clips_coefficients_key", ["coefficients_key"]),
    ("jobs", "ix_jobs_list", ["tenant_id", "created_at", "id"]),
    ("jobs", "ix_jobs_mesh_id", ["mesh_id"]),
]


def upgrade() -> None:
    for table, name, columns in INDEXES:
        with op.batch_alter_table(table, schema=None) as batch_op:
            batch_op.create_index(name, columns, unique=False)


def downgrade() -> None:
    for table, name, _ in reversed(INDEXES):
        with op.batch_alter_table(table, schema=None) as batch_op:
            batch_op.drop_index(name)
