// Render the built-in "lights" scene with libOpenBokeh and write it as an EXR.
//   make_scene out.exr [width height]
#include <bokeh/io.h>
#include <bokeh/scene.h>

#include <cstdlib>
#include <iostream>

int main(int argc, char* argv[])
{
    if (argc != 2 && argc != 4) {
        std::cerr << "usage: make_scene OUT.exr [WIDTH HEIGHT]\n";
        return 1;
    }
    bokeh::SceneOptions opts;
    if (argc == 4) {
        opts.width  = std::atoi(argv[2]);
        opts.height = std::atoi(argv[3]);
    }
    OIIO::ImageBuf img;
    if (!bokeh::make_scene(img, "lights", opts)) {
        std::cerr << "make_scene: " << img.geterror() << "\n";
        return 1;
    }
    std::string err;
    if (!bokeh::write_image(img, argv[1], {}, err)) {
        std::cerr << "make_scene: " << err << "\n";
        return 1;
    }
    std::cout << "wrote " << argv[1] << " (" << opts.width << "x" << opts.height << ")\n";
    return 0;
}
