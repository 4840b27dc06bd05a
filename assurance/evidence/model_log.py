"""The model development log (AMLAS [U], with the internal test results [X]) from the network's model card and the
cards of the monitors the run used: data, schedule, selection rule, validation figures, and what the test split was
used for."""

from __future__ import annotations

from typing import Any

from assurance.evidence.facts import gate_features
from assurance.evidence.records import model_cards


def _pct(v: Any) -> str:
    return f"{float(v):.3f}" if isinstance(v, int | float) else "n/a"


def network_rows(card: dict[str, Any], test_sha: str) -> list[dict[str, str]]:
    """The network's development, item by item, from its model card."""
    t = card.get("training") or {}
    cfg, data, arch = t.get("config") or {}, t.get("data") or {}, card.get("architecture") or {}
    ev = card.get("evaluation") or {}
    enc = t.get("encoder_init") or {}
    used = {k: (v or {}).get("sha256") for k, v in data.items()}
    test_use = ("none: the card names only " + ", ".join(f"{k} ({(v or {}).get('path')})" for k, v in data.items())
                + "; the run's test data hash is none of theirs" if test_sha not in used.values()
                else "THE RUN'S TEST DATA WAS USED IN DEVELOPMENT (its hash is in the card)")
    return [
        {"item": "Network", "value": f"{arch.get('name', '?')}, {card.get('parameters', '?')} parameters, "
                                     f"{arch.get('num_classes', '?')} classes; weights {card.get('weights_file')} "
                                     f"SHA-256 {str(card.get('weights_sha256', ''))[:16]}"},
        {"item": "Initialisation", "value": (f"encoder from {enc.get('package')} {enc.get('version')} "
                                             f"({enc.get('file')}, SHA-256 {str(enc.get('sha256', ''))[:16]})"
                                             if enc else str(t.get("init") or "random"))},
        {"item": "Data", "value": "; ".join(f"{k}: {(v or {}).get('path')} ({(v or {}).get('images')} images, "
                                            f"SHA-256 {str((v or {}).get('sha256', ''))[:16]})"
                                            for k, v in data.items())},
        {"item": "Schedule", "value": f"{cfg.get('steps')} steps, batch {cfg.get('batch')}, crop {cfg.get('crop')}, "
                                      f"lr {cfg.get('lr')} (warm-up {cfg.get('warmup')}), weight decay "
                                      f"{cfg.get('weight_decay')}, seed {t.get('seed')}, {t.get('device', '?')}, "
                                      f"torch {t.get('torch_version', '?')}"},
        {"item": "Loss", "value": str(t.get("loss", cfg.get("loss", "?")))},
        {"item": "Augmentations", "value": ", ".join(t.get("augmentations") or []) + "; not used (the test "
                                           "perturbations): " + ", ".join(t.get("not_used_augmentations") or [])},
        {"item": "Selection rule", "value": f"the checkpoint with the best validation score (mean of working-"
                                            f"resolution and HD-patch mIoU on the validation split), evaluated every "
                                            f"{cfg.get('eval_every')} steps: step {t.get('best_step')} of "
                                            f"{t.get('total_steps')}"},
        {"item": "Validation figures", "value": f"mIoU {_pct((ev.get('working_resolution') or {}).get('miou'))} "
                                                f"(working resolution), "
                                                f"{_pct((ev.get('hd_patches') or {}).get('miou'))} "
                                                f"(HD patches) on {(ev.get('data') or {}).get('path')} "
                                                f"({ev.get('frames')} frames)"},
        {"item": "Test split used for", "value": test_use},
    ]


def monitor_rows(monitors: dict[str, dict[str, Any]]) -> list[dict[str, str]]:
    """The development of the monitors the run used, from their cards (the frame gate as its file says it is)."""
    rows = []
    learned = monitors.get("learned.json")
    if learned:
        sel = learned.get("selection") or {}
        rows.append({"item": "Learned monitor", "value": f"{learned.get('model')}; C chosen by held-out AUROC "
                     f"({_pct(sel.get('held_out_auroc'))}), threshold for recall {sel.get('recall_target')} "
                     f"(held-out recall {_pct(sel.get('held_out_recall'))}); fitted on segmentation network "
                     f"{str((learned.get('weights') or {}).get('sha256', ''))[:16]}"})
    verifier = monitors.get("verifier.json")
    if verifier:
        crop, net, fusion = verifier.get("crop") or {}, verifier.get("network") or {}, verifier.get("fusion") or {}
        fused = (f"; fused with the learned monitor (weight {fusion.get('weight')}, held-out AUROC "
                 f"{_pct((fusion.get('held_out') or {}).get('auroc'))})" if fusion else "")
        rows.append({"item": "Candidate verifier", "value": f"{net.get('name')} ({net.get('encoder')}) on "
                     f"{crop.get('size')} px crops of the disc and {crop.get('margin')} radii around it; held-out "
                     f"AUROC {_pct((verifier.get('held_out') or {}).get('auroc'))}{fused}; its ONNX network "
                     f"{str((verifier.get('onnx') or {}).get('sha256', ''))[:16]}, fitted on segmentation network "
                     f"{str((verifier.get('weights') or {}).get('sha256', ''))[:16]}"})
    cal = monitors.get("calibration.json")
    if cal:
        rows.append({"item": "Calibration card", "value": f"{cal.get('monitor')}: {cal.get('method')}; "
                                                          f"{cal.get('guarantee')}"})
    gate = monitors.get("frame_gate.json")
    if gate:
        rows.append({"item": "Frame gate", "value": f"{gate_features(gate)}; threshold at quantile "
                                                    f"{gate.get('quantile')} of the validation scores"})
    return rows


def model_log(manifest: dict[str, Any], calibration_card: Any = None) -> dict[str, Any]:
    """The model development log of the run's network and monitors (empty parts when a card is missing)."""
    card, monitors = model_cards(manifest, calibration_card)
    test_sha = str((manifest.get("data") or {}).get("sha256") or "")
    history = [{"step": h.get("step"), "loss": f"{h.get('loss', float('nan')):.3f}",
                "val_working": _pct(h.get("val_miou_working")), "val_hd": _pct(h.get("val_miou_hd")),
                "score": _pct(h.get("score"))} for h in ((card or {}).get("training") or {}).get("history") or []]
    return {"network": network_rows(card, test_sha) if card else [], "history": history,
            "monitors": monitor_rows(monitors), "card": "model card found" if card else
            "no model card beside the run's weights"}
