"""The light source (MCmatlab's ``model.MC.lightSource``, :mod:`~mcmatlab_py.light.source`,
its launch kernels in ``_sources``) and the light collector
(:mod:`~mcmatlab_py.light.collector`)."""

from .collector import DepositionCriteria, LightCollector
from .source import IntensityDistribution, LightSource, sample_light_source, source_kind

__all__ = ["DepositionCriteria", "IntensityDistribution", "LightCollector", "LightSource",
           "sample_light_source", "source_kind"]
