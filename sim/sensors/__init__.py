"""Sensor models: the instruments, their errors and the delivery of their samples.

A :class:`Sensor` samples the truth of a motion source at its rate and passes the samples
through stages, each a frozen settings dataclass with ``apply(stream, rng)``. All randomness
comes from the injected ``numpy.random.Generator``.

=====================  ===================================================================
``stream``             :class:`SampleStream`, :class:`Sensor` (the sampler), :class:`Latency`;
                       sample sources read in blocks (``ArraySamples``, ``SampledSamples``)
``sonomicrometry``     the physical sonomicrometer (time of flight, quantisation, speed of
                       sound, leading-edge error, cycle slips), :func:`sonomicrometry`
``crystals``           :class:`CrystalArray`, the reference base and POI crystal geometry
``trilateration``      :func:`trilaterate`, 3-D positions from ranges
``white``              additive white Gaussian noise (:class:`WhiteNoise`, :func:`white`)
``events``             :class:`EchoOutliers`, :class:`Dropouts`
``faults``             injected faults, each kind declared once: a freeze, a jump, missing
                       samples, stuck encoders; ``FaultySamples``
``playback``           delivery to the control rate: :class:`Upsample`, :data:`PLAYBACKS`,
                       made block by block (``UpsampledSamples``, ``sensor_samples``)
``ultrasound``         3-D ultrasound (Yuen et al.): 28 Hz, σ = 1.3 mm, 68 ms latency
``video``              stereo-endoscopic video tracking: 25 Hz, σ = 0.15 mm, one frame late
``encoder``            :class:`Encoder`, quantised joint angles
``names``              :func:`sensor_from_name`, :data:`SENSORS`
=====================  ===================================================================
"""

from rhmpc.sim.sensors.crystals import CrystalArray
from rhmpc.sim.sensors.encoder import Encoder
from rhmpc.sim.sensors.events import Dropouts, EchoOutliers
from rhmpc.sim.sensors.names import DEFAULT_PLAYBACK, SENSORS, ideal, sensor_from_name
from rhmpc.sim.sensors.playback import PLAYBACKS, Upsample, playback
from rhmpc.sim.sensors.sonomicrometry import Sonomicrometer, SonomicrometrySettings, sonomicrometry
from rhmpc.sim.sensors.stream import Latency, SampleStream, Sensor, Stage
from rhmpc.sim.sensors.trilateration import dilution, trilaterate
from rhmpc.sim.sensors.ultrasound import UltrasoundSettings, ultrasound
from rhmpc.sim.sensors.video import VideoSettings, video
from rhmpc.sim.sensors.white import WhiteNoise, WhiteSettings, white

__all__ = [
    "DEFAULT_PLAYBACK", "PLAYBACKS", "SENSORS", "CrystalArray", "Dropouts", "EchoOutliers",
    "Encoder", "Latency", "SampleStream", "Sensor", "Sonomicrometer", "SonomicrometrySettings",
    "Stage", "UltrasoundSettings", "Upsample", "VideoSettings", "WhiteNoise", "WhiteSettings",
    "dilution", "ideal", "playback", "sensor_from_name", "sonomicrometry", "trilaterate",
    "ultrasound", "video", "white",
]
