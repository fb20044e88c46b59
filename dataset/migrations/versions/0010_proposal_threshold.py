"""proposal threshold: each scan's threshold in force, and the fate ``hidden``

Revision ID: 0010
Revises: 0009

Scans get the score under which their proposals are hidden on the Annotate page (0 for existing
scans: they kept only what scored at least the old fixed threshold, so none of theirs is hidden);
a proposal's fate may now be ``hidden`` (under the threshold and left untouched on submit).
"""

import sqlalchemy as sa
from alembic import op

revision = "0010"
down_revision = "0009"
branch_labels = None
depends_on = None

OLD_FATES = ("pending", "accepted", "edited", "rejected")
NEW_FATES = (*OLD_FATES, "hidden")


def _fate(values: tuple[str, ...]) -> sa.Enum:
    return sa.Enum(*values, name="proposalfate", native_enum=False, create_constraint=True, length=32)


def upgrade() -> None:
    with op.batch_alter_table("proposal_scans") as batch:
        batch.add_column(sa.Column("threshold", sa.Double(), server_default="0", nullable=False))
    with op.batch_alter_table("proposals") as batch:
        batch.alter_column("fate", existing_type=_fate(OLD_FATES), type_=_fate(NEW_FATES), existing_nullable=False)


def downgrade() -> None:
    # A hidden proposal was left untouched: the old schema's word for that is rejected.
    op.execute("UPDATE proposals SET fate = 'rejected' WHERE fate = 'hidden'")
    with op.batch_alter_table("proposals") as batch:
        batch.alter_column("fate", existing_type=_fate(NEW_FATES), type_=_fate(OLD_FATES), existing_nullable=False)
    with op.batch_alter_table("proposal_scans") as batch:
        batch.drop_column("threshold")
