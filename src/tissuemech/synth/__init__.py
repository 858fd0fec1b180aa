"""Virtual parallel-plate rheometer: protocols, plate physics, instrument, hidden effects, RheoCompass writer."""
from .generator import build_model, generate_dataset, load_config
from .instrument import Artefacts, Geometry, InstrumentSettings, run_protocol
from .protocols import build_protocol

__all__ = ["Artefacts", "Geometry", "InstrumentSettings", "build_model", "build_protocol", "generate_dataset",
           "load_config", "run_protocol"]
