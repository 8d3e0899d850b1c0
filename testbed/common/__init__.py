"""The shared library of both nodes (the ECS paper's ``common``).

What the operator and the vehicle must agree on lives here: the component types they replicate
(with stable ids and owners) and the link codecs that carry them — the full change-set codec for
wideband links and the compact teleop codec for narrow ones. Imports: ``ecs``, ``protocol``,
``config``, numpy; never ``vehicle`` or ``operator``.
"""

# The full change-set codec (wideband links), its two ends and its per-type field codec.
from testbed.common.changeset import ChangeSetCodec as ChangeSetCodec
from testbed.common.changeset_receiver import ApplyResult as ApplyResult
from testbed.common.changeset_receiver import ApplyStatus as ApplyStatus
from testbed.common.changeset_receiver import ChangeSetReceiver as ChangeSetReceiver
from testbed.common.changeset_sender import ChangeSetSender as ChangeSetSender
from testbed.common.field_layouts import FieldDecodeError as FieldDecodeError
from testbed.common.fieldcodec import FieldCodec as FieldCodec
from testbed.common.fieldcodec import compile_codec as compile_codec
