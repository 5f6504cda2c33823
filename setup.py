"""Build the optional compiled ray-casting loop (sot_apps/raycast/_embree_trace.c).

Everything else is in pyproject.toml. The extension is optional: without a C compiler the install still
succeeds and ray casting falls back to embreex (sot_apps.raycast). It is a plain shared library
loaded with ctypes; it finds Embree at run time in the embreex wheel, so nothing links against it here.
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "sot_apps.raycast._embree_trace",
            sources=["sot_apps/raycast/_embree_trace.c"],
            libraries=["dl", "m"],
            extra_compile_args=["-O3", "-fvisibility=hidden", "-std=c99"],
            optional=True,
        )
    ]
)
