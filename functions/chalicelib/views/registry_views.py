"""The model registry's charts, drawn from the figures the domain gives (chalicelib.domain.model_registry)."""
from __future__ import annotations

from dataclasses import dataclass

from markupsafe import Markup

from chalicelib.domain.model_registry import Curve, ModelDetail, RegistryView
from chalicelib.views import svg_plots
from chalicelib.views.racer_names import ProfilesBySub, shown_racer_names


@dataclass(frozen=True)
class RegistryPlots:
    lap_time_plot: Markup
    completion_plot: Markup
    track_plot: Markup


def _series(curves: list[Curve]) -> list[svg_plots.Series]:
    return [svg_plots.Series(c.label, c.points) for c in curves if c.points]


def registry_plots(view: RegistryView) -> RegistryPlots:
    labels = view.version_labels
    return RegistryPlots(
        lap_time_plot=svg_plots.line_chart(_series(view.lap_curves), labels, title="Best lap over model versions",
                                           y_label="seconds", testid="plot-lap-times"),
        completion_plot=svg_plots.line_chart(_series(view.completion_curves), labels,
                                             title="Completion over model versions", y_label="%",
                                             testid="plot-completion"),
        track_plot=svg_plots.bar_chart(view.track_bests, title="Best lap per track (all versions)", y_label="seconds",
                                       testid="plot-tracks"))


def loss_plot(detail: ModelDetail) -> Markup | None:
    """Training loss per epoch; None for a model without a lineage."""
    if not detail.lineage:
        return None
    epochs = max((len(c.points) for c in detail.loss_curves), default=0)
    return svg_plots.line_chart(_series(detail.loss_curves), [str(i + 1) for i in range(epochs)],
                                title="Training loss per epoch", y_label="loss", testid="plot-loss")


def registry_racer_names(view: RegistryView, profiles: ProfilesBySub) -> dict[str, str]:
    """The staff registry's Racer column: display names, told apart among every racer it lists (one batch read)."""
    return shown_racer_names([(row.model.owner_sub, row.model.owner_username) for row in view.rows], profiles)
