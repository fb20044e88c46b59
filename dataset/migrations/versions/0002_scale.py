"""scale: the newest verdict on the frame, maintained counts, an index per grid filter

Revision ID: 0002
Revises: 0001

Upgrades a populated database: the new columns are backfilled in batches of frame ids, the counts
are computed once, and only then do the triggers that keep them take over (migrations run with the
app stopped). The triggers run in the writing transaction, so every writer — the prefilter and
review services, ingest, a script's bulk UPDATE — keeps the pointer and the counts right.

Later migrations: on SQLite, a batch operation that recreates ``frames``, ``samples`` or
``prefilter_results`` drops their triggers; call ``create_triggers`` from this module again after it.
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import context, op

revision = '0002'
down_revision = '0001'
branch_labels = None
depends_on = None

BATCH = 50_000  # frame ids per backfill statement; the config attribute ``backfill_batch`` overrides it

# counts table → (source table, {key column: expression over the source row}), in key order.
_COUNTED = {
    "frame_counts": ("frames", {"video_id": "{r}.video_id", "state": "{r}.state",
                                "keep": "COALESCE(CAST({r}.prefilter_keep AS INTEGER), -1)"}),
    "sample_counts": ("samples", {"state": "{r}.state", "flagged": "{r}.flagged"}),
}
_WATCHED = {"frame_counts": ("video_id", "state", "prefilter_keep"), "sample_counts": ("state", "flagged")}


def _enum(name: str, values: tuple[str, ...]) -> sa.Enum:
    return sa.Enum(*values, name=name, native_enum=False, create_constraint=True, length=32)


_FRAME_STATES = ('ingested', 'prefiltered', 'approved', 'rejected', 'annotated', 'generated', 'accepted', 'deleted')
_SAMPLE_STATES = ('generated', 'accepted', 'rejected')


def upgrade() -> None:
    op.add_column('frames', sa.Column('prefilter_result_id', sa.Integer(), nullable=True))
    op.add_column('frames', sa.Column('prefilter_keep', sa.Boolean(), nullable=True))
    op.create_table('frame_counts',
                    sa.Column('video_id', sa.Integer(), autoincrement=False, nullable=False),
                    sa.Column('state', _enum('framestate', _FRAME_STATES), nullable=False),
                    sa.Column('keep', sa.Integer(), autoincrement=False, nullable=False),
                    sa.Column('n', sa.Integer(), nullable=False),
                    sa.PrimaryKeyConstraint('video_id', 'state', 'keep', name=op.f('pk_frame_counts')))
    op.create_table('sample_counts',
                    sa.Column('state', _enum('samplestate', _SAMPLE_STATES), nullable=False),
                    sa.Column('flagged', sa.Boolean(), nullable=False),
                    sa.Column('n', sa.Integer(), nullable=False),
                    sa.PrimaryKeyConstraint('state', 'flagged', name=op.f('pk_sample_counts')))
    _backfill()
    op.drop_index('ix_frames_state_video', table_name='frames')
    op.create_index('ix_frames_state_video_index', 'frames', ['state', 'video_id', 'index'])
    op.create_index('ix_frames_state_keep_video_index', 'frames', ['state', 'prefilter_keep', 'video_id', 'index'])
    op.create_index('ix_samples_state_id', 'samples', ['state', 'id'])
    op.create_index('ix_samples_flagged_id', 'samples', ['flagged', 'id'])
    op.drop_index('ix_jobs_state', table_name='jobs')
    op.create_index('ix_jobs_state_id', 'jobs', ['state', 'id'])
    op.create_index('ix_jobs_created_by_id', 'jobs', ['created_by_id', 'id'])
    op.create_index('ix_annotations_user_updated', 'annotations', ['user_id', 'updated_at'])
    op.create_index('ix_annotations_lease_user_id', 'annotations', ['lease_user_id'])
    create_triggers()


def _backfill() -> None:
    conn = op.get_bind()
    batch = int(context.config.attributes.get("backfill_batch", BATCH))
    lo, hi = conn.execute(sa.text("SELECT min(id), max(id) FROM frames")).one()
    start = lo
    while start is not None and start <= hi:
        # One UPDATE … FROM per batch (SQLite ≥ 3.33 and PostgreSQL alike): each row is written once.
        conn.execute(sa.text(
            "UPDATE frames SET prefilter_result_id = latest.rid, prefilter_keep = p.keep "
            "FROM (SELECT frame_id, max(id) AS rid FROM prefilter_results "
            "      WHERE frame_id >= :lo AND frame_id < :hi GROUP BY frame_id) AS latest "
            "JOIN prefilter_results AS p ON p.id = latest.rid "
            "WHERE frames.id = latest.frame_id"), {"lo": start, "hi": start + batch})
        start += batch
    for counts, (source, keys) in _COUNTED.items():
        columns = ", ".join(keys)
        exprs = ", ".join(e.format(r=source) for e in keys.values())
        conn.execute(sa.text(f"INSERT INTO {counts} ({columns}, n) SELECT {exprs}, count(*) FROM {source} "
                             f"GROUP BY {exprs}"))


def create_triggers() -> None:
    """The triggers that keep ``frames.prefilter_*`` and the counts tables in step (idempotent)."""
    drop_triggers()
    for statement in (_postgresql_triggers() if op.get_bind().dialect.name == "postgresql" else _sqlite_triggers()):
        op.execute(statement)


def drop_triggers() -> None:
    if op.get_bind().dialect.name == "postgresql":
        op.execute("DROP FUNCTION IF EXISTS prefilter_latest() CASCADE")
        for counts in _COUNTED:
            op.execute(f"DROP FUNCTION IF EXISTS {counts}_apply() CASCADE")
        return
    op.execute("DROP TRIGGER IF EXISTS prefilter_latest")
    for counts in _COUNTED:
        for event in ("insert", "delete", "update"):
            op.execute(f"DROP TRIGGER IF EXISTS {counts}_{event}")


_LATEST = ("UPDATE frames SET prefilter_result_id = NEW.id, prefilter_keep = NEW.keep "
           "WHERE id = NEW.frame_id AND (prefilter_result_id IS NULL OR prefilter_result_id < NEW.id)")


def _add(counts: str, row: str) -> str:
    keys = _COUNTED[counts][1]
    return (f"INSERT INTO {counts} ({', '.join(keys)}, n) VALUES ({', '.join(e.format(r=row) for e in keys.values())}, 1) "
            f"ON CONFLICT ({', '.join(keys)}) DO UPDATE SET n = {counts}.n + 1")


def _remove(counts: str, row: str) -> list[str]:
    match = " AND ".join(f"{k} = {e.format(r=row)}" for k, e in _COUNTED[counts][1].items())
    # Rows that reach zero go, so a deleted video leaves nothing behind.
    return [f"UPDATE {counts} SET n = n - 1 WHERE {match}", f"DELETE FROM {counts} WHERE {match} AND n <= 0"]


def _sqlite_triggers() -> list[str]:
    out = [f"CREATE TRIGGER prefilter_latest AFTER INSERT ON prefilter_results BEGIN {_LATEST}; END"]
    for counts, (source, _) in _COUNTED.items():
        watched = _WATCHED[counts]
        changed = " OR ".join(f"OLD.{c} IS NOT NEW.{c}" for c in watched)
        out += [
            f"CREATE TRIGGER {counts}_insert AFTER INSERT ON {source} BEGIN {_add(counts, 'NEW')}; END",
            f"CREATE TRIGGER {counts}_delete AFTER DELETE ON {source} BEGIN {'; '.join(_remove(counts, 'OLD'))}; END",
            f"CREATE TRIGGER {counts}_update AFTER UPDATE OF {', '.join(watched)} ON {source} WHEN {changed} "
            f"BEGIN {'; '.join(_remove(counts, 'OLD'))}; {_add(counts, 'NEW')}; END",
        ]
    return out


def _postgresql_triggers() -> list[str]:
    out = [f"CREATE FUNCTION prefilter_latest() RETURNS trigger LANGUAGE plpgsql AS $$ BEGIN {_LATEST}; "
           "RETURN NULL; END $$",
           "CREATE TRIGGER prefilter_latest AFTER INSERT ON prefilter_results FOR EACH ROW "
           "EXECUTE FUNCTION prefilter_latest()"]
    for counts, (source, _) in _COUNTED.items():
        watched = _WATCHED[counts]
        changed = " OR ".join(f"OLD.{c} IS DISTINCT FROM NEW.{c}" for c in watched)
        out += [
            f"CREATE FUNCTION {counts}_apply() RETURNS trigger LANGUAGE plpgsql AS $$ BEGIN "
            f"IF TG_OP IN ('UPDATE', 'DELETE') THEN {'; '.join(_remove(counts, 'OLD'))}; END IF; "
            f"IF TG_OP IN ('UPDATE', 'INSERT') THEN {_add(counts, 'NEW')}; END IF; RETURN NULL; END $$",
            f"CREATE TRIGGER {counts}_insert AFTER INSERT ON {source} FOR EACH ROW EXECUTE FUNCTION {counts}_apply()",
            f"CREATE TRIGGER {counts}_delete AFTER DELETE ON {source} FOR EACH ROW EXECUTE FUNCTION {counts}_apply()",
            f"CREATE TRIGGER {counts}_update AFTER UPDATE OF {', '.join(watched)} ON {source} FOR EACH ROW "
            f"WHEN ({changed}) EXECUTE FUNCTION {counts}_apply()",
        ]
    return out


def downgrade() -> None:
    drop_triggers()
    op.drop_index('ix_annotations_lease_user_id', table_name='annotations')
    op.drop_index('ix_annotations_user_updated', table_name='annotations')
    op.drop_index('ix_jobs_created_by_id', table_name='jobs')
    op.drop_index('ix_jobs_state_id', table_name='jobs')
    op.create_index('ix_jobs_state', 'jobs', ['state'])
    op.drop_index('ix_samples_flagged_id', table_name='samples')
    op.drop_index('ix_samples_state_id', table_name='samples')
    op.drop_index('ix_frames_state_keep_video_index', table_name='frames')
    op.drop_index('ix_frames_state_video_index', table_name='frames')
    op.create_index('ix_frames_state_video', 'frames', ['state', 'video_id'])
    op.drop_table('sample_counts')
    op.drop_table('frame_counts')
    with op.batch_alter_table('frames') as batch_op:
        batch_op.drop_column('prefilter_keep')
        batch_op.drop_column('prefilter_result_id')
