"""voxelastic job specification: Pydantic v2 models of the JSON job spec and its JSON Schema.

Typical use::

    from schemas import parse_job, SpecError

    try:
        spec = parse_job(open("job.json").read())   # JSON text, bytes or a dict
    except SpecError as exc:
        print("\\n".join(exc.errors))                # "loads.gravity: expected 3 components ..."

``python -m schemas.export`` regenerates ``schemas/json/job.schema.json`` (``--check`` verifies it).
Modules: ``base`` (shared conventions), ``regions``, ``job`` (the job and parsing).
This package is a leaf: it imports neither ``engine`` nor ``service``.
"""

from .job import Analysis
from .job import Boundary
from .job import DGMethod
from .job import DisplacementBoundary
from .job import DynamicAnalysis
from .job import GeometrySpec
from .job import GridSpec
from .job import JobSpec
from .job import LoadsSpec
from .job import MaterialSpec
from .job import Method
from .job import OutputSpec
from .job import PressureBoundary
from .job import QuasistaticAnalysis
from .job import SolverSpec
from .job import SpecError
from .job import StaggeredMethod
from .job import StaticAnalysis
from .job import TractionBoundary
from .job import format_errors
from .job import job_json_schema
from .job import parse_job
from .regions import AllRegion
from .regions import BoxRegion
from .regions import Halfspace
from .regions import HalfspaceRegion
from .regions import Region
from .regions import Sphere
from .regions import SphereRegion

__all__ = [
    "AllRegion",
    "Analysis",
    "Boundary",
    "BoxRegion",
    "DGMethod",
    "DisplacementBoundary",
    "DynamicAnalysis",
    "GeometrySpec",
    "GridSpec",
    "Halfspace",
    "HalfspaceRegion",
    "JobSpec",
    "LoadsSpec",
    "MaterialSpec",
    "Method",
    "OutputSpec",
    "PressureBoundary",
    "QuasistaticAnalysis",
    "Region",
    "SolverSpec",
    "SpecError",
    "Sphere",
    "SphereRegion",
    "StaggeredMethod",
    "StaticAnalysis",
    "TractionBoundary",
    "format_errors",
    "job_json_schema",
    "parse_job",
]
