// A GLTFLoader plugin for MOZ_lightmap ({index, texCoord, intensity}) as Radiosity Baker writes it:
// the texture is an 8-bit PNG in RGBM or RGBD (extras.encoding, extras.range); a float lightmap
// (glTF's core allows no float texture) is an image file in a buffer view named by
// extras.float_image = {encoding, bufferView, mimeType}: Radiance HDR (image/vnd.radiance) or
// OpenEXR (image/x-exr), loaded here in place of the texture, its RGBM stand-in. Texels hold
// lighting = irradiance/π (Hubs' convention); three.js adds lightMap × lightMapIntensity to the
// irradiance and multiplies by albedo/π, so lightMapIntensity = π × intensity.
import { DataTexture, LinearFilter, NoColorSpace, ShaderChunk } from 'three';
import { HDRLoader } from 'three/addons/loaders/HDRLoader.js';
import { EXRLoader } from 'three/addons/loaders/EXRLoader.js';

const NAME = 'MOZ_lightmap';

// GLSL that replaces three.js's lightmap sampling with the decode of an 8-bit encoding.
const DECODE = {
  rgbm: 'lightMapTexel.rgb * lightMapTexel.a * rbLightmapRange',
  rgbd: 'lightMapTexel.rgb * (rbLightmapRange / 255.0) / max(lightMapTexel.a, 1.0 / 255.0)',
};

export class MozLightmapPlugin {
  constructor(parser) {
    this.parser = parser;
    this.name = NAME;
  }

  async floatTexture(page) {
    const Loader = page.mimeType === 'image/vnd.radiance' ? HDRLoader : EXRLoader;
    const buffer = await this.parser.getDependency('bufferView', page.bufferView);
    const data = new Loader().parse(buffer);
    const texture = new DataTexture(data.data, data.width, data.height, data.format, data.type);
    // glTF: the first row of the image file is v = 0, the opposite of what the loader's own
    // flipY is for (HDRLoader keeps the file's rows, flipY true; EXRLoader reverses them, false)
    texture.flipY = !data.flipY;
    texture.minFilter = texture.magFilter = LinearFilter;
    texture.generateMipmaps = false;
    texture.needsUpdate = true;
    return texture;
  }

  async extendMaterialParams(materialIndex, params) {
    const ext = (this.parser.json.materials[materialIndex].extensions || {})[NAME];
    if (!ext) return;
    let extras = ext.extras || {};
    let texture;
    if (extras.float_image) {
      texture = await this.floatTexture(extras.float_image);
      extras = { encoding: extras.float_image.encoding };  // nothing to decode in the shader
    } else {
      texture = await this.parser.loadTexture(ext.index);
      texture.colorSpace = NoColorSpace;  // encoded data, not colour
    }
    texture.channel = ext.texCoord || 0;
    params.lightMap = texture;
    params.lightMapIntensity = Math.PI * (ext.intensity ?? 1.0);
    params.userData = { ...(params.userData || {}), rbLightmap: extras };
  }

  afterRoot(gltf) {
    gltf.scene.traverse((object) => {
      const materials = object.material ? [].concat(object.material) : [];
      for (const material of materials) {
        const extras = material.userData.rbLightmap;
        if (!extras || !(extras.encoding in DECODE)) continue;
        material.onBeforeCompile = (shader) => {
          shader.uniforms.rbLightmapRange = { value: extras.range };
          const chunk = ShaderChunk.lights_fragment_maps.replace(
            'lightMapTexel.rgb * lightMapIntensity',
            `(${DECODE[extras.encoding]}) * lightMapIntensity`);
          shader.fragmentShader = 'uniform float rbLightmapRange;\n' +
            shader.fragmentShader.replace('#include <lights_fragment_maps>', chunk);
        };
        material.customProgramCacheKey = () => extras.encoding;
        material.needsUpdate = true;
      }
    });
  }
}
