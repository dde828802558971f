"""What a session looks like in Foxglove, derived from what the session holds: the rig's frame
tree (frame_tree), the skin's display-rate totals and centre of pressure (skin_summary), the
per-rig layouts in the app's import format (layout), and the live WebSocket view (live)."""

from layerskin_exp.log.view.frame_tree import FrameTree
from layerskin_exp.log.view.skin_summary import SkinView

__all__ = ["FrameTree", "SkinView"]
